"""Does a planned code read? Render the job's marks around each code as the beam marks them
(every path a line of the beam's width) and decode the picture with zxing-cpp.

The marks are taken from the job itself: its x, y for a flat mark, or unrolled along the
surface for wrap (each point's distance from the anchor along the unroll direction is
replaced by the arc length of the job's own height profile), so a projection that bends or
stretches the code is caught. The picture is drawn in the code's own axes (a reader held
square to the code) over the symbol and its quiet zone plus one quiet zone more, so a mark
that strays into the quiet zone counts."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from insitu.patterns.codes import SYMBOLOGIES
from insitu.patterns.model import Pattern

PX_PER_BEAM = 3      # drawing resolution: pixels across the beam
PX_PER_MODULE = 8    # the picture handed to the reader, at most this many pixels per module


@dataclass(frozen=True)
class CodeCheck:
    """One code's verdict: ``name`` (the spec), ``text`` it must read, ``decoded`` (what the
    reader read, None: nothing), ``module_mm`` as placed; ``ok`` when they match."""

    name: str
    text: str
    decoded: str | None
    module_mm: float

    @property
    def ok(self) -> bool:
        return self.decoded == self.text


def unrolled(paths3d: list[np.ndarray], anchor, direction_deg: float) -> list[np.ndarray]:
    """(N, 3) mm paths on a surface → (N, 2) mm: distance along ``direction_deg`` from
    ``anchor`` replaced by the arc length over the height profile z(a) of all the points
    (binned, interpolated), the cross distance kept."""
    d = np.array([math.cos(math.radians(direction_deg)), math.sin(math.radians(direction_deg))])
    n = np.array([-d[1], d[0]])
    anchor = np.asarray(anchor, np.float64)
    pts = np.vstack(paths3d)
    a = (pts[:, :2] - anchor) @ d
    span = float(np.ptp(a)) or 1.0
    edges = np.linspace(a.min(), a.max(), max(2, min(400, int(span / 0.05))) + 1)
    idx = np.clip(np.searchsorted(edges, a, side="right") - 1, 0, len(edges) - 2)
    cnt = np.bincount(idx, minlength=len(edges) - 1)
    zsum = np.bincount(idx, pts[:, 2], minlength=len(edges) - 1)
    mid = 0.5 * (edges[1:] + edges[:-1])
    z = np.interp(mid, mid[cnt > 0], zsum[cnt > 0] / cnt[cnt > 0])
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(mid), np.diff(z)))])
    s -= np.interp(0.0, mid, s)        # arc length 0 at the anchor

    def one(p):
        q = p[:, :2] - anchor
        return anchor + np.outer(np.interp(q @ d, mid, s, left=None, right=None), d) \
            + np.outer(q @ n, n)
    return [one(p) for p in paths3d]


def render(paths_xy: list[np.ndarray], origin, axes: np.ndarray, size_mm, beam_mm: float,
           px_mm: float) -> np.ndarray:
    """(H, W) uint8 picture, white ground, black marks: ``paths_xy`` (N, 2) mm drawn as lines
    ``beam_mm`` wide, in the frame of ``origin`` (2,) and unit ``axes`` (2, 2) rows u, v,
    over ``size_mm`` (u, v) at ``px_mm`` per pixel (v up in the picture)."""
    w, h = (int(math.ceil(s / px_mm)) for s in size_mm)
    img = np.full((h, w), 255, np.uint8)
    thick = max(1, round(beam_mm / px_mm))
    shift = 4
    for p in paths_xy:
        uv = (p - origin) @ axes.T / px_mm
        inside = ((uv[:, 0] > -thick) & (uv[:, 0] < w + thick) & (uv[:, 1] > -thick)
                  & (uv[:, 1] < h + thick))
        if not inside.any():
            continue
        pix = np.column_stack([uv[:, 0], h - uv[:, 1]]) * (1 << shift)
        cv2.polylines(img, [np.round(pix).astype(np.int32)], False, 0, thick, cv2.LINE_8,
                      shift)
    return img


def decode(img: np.ndarray, symbology: str) -> str | None:
    """The text zxing-cpp reads in ``img`` for ``symbology`` (None: nothing read)."""
    import zxingcpp

    fmt = getattr(zxingcpp.BarcodeFormat, SYMBOLOGIES[symbology][0])
    found = zxingcpp.read_barcodes(img, formats=fmt, try_rotate=True, try_downscale=True)
    return found[0].text if found else None


def check_code(pattern: Pattern, paths_xy: list[np.ndarray], beam_mm: float
               ) -> tuple[CodeCheck, np.ndarray]:
    """Decode the code of the placed ``pattern`` (its frame: the symbol and quiet zone) from
    the marks ``paths_xy`` (N, 2) mm. Returns the verdict and the picture read."""
    code, f = pattern.code, pattern.frame
    u = (f[1] - f[0]) / np.linalg.norm(f[1] - f[0])
    v = np.array([-u[1], u[0]])
    module = float(np.linalg.norm(f[1] - f[0])) / (code.cols + 2 * code.quiet)
    margin = max(code.quiet, 2) * module
    size = (float(np.linalg.norm(f[1] - f[0])) + 2 * margin,
            float(np.linalg.norm(f[3] - f[0])) + 2 * margin)
    origin = f[0] - margin * (u + v)
    px = min(beam_mm / PX_PER_BEAM, module / PX_PER_MODULE)
    img = render(paths_xy, origin, np.vstack([u, v]), size, beam_mm, px)
    scale = module / PX_PER_MODULE / px
    if scale > 1.01:
        img = cv2.resize(img, (max(1, round(img.shape[1] / scale)),
                               max(1, round(img.shape[0] / scale))),
                         interpolation=cv2.INTER_AREA)
    return CodeCheck(pattern.name, code.text, decode(img, code.symbology), module), img
