"""What the vector sources (``svg.py``, ``dxf.py``) share: curve flattening, units, the size
guard and one-line failures.

Curves are flattened to polylines that stay within ``tol_mm`` of the true curve (default
0.002 mm, far below a 40 µm laser line). Any failure to read a file is one FormatError. A
drawing file is at most ``MAX_DRAWING_BYTES``; coordinates that are not finite are refused
before anything is flattened, and a file flattens to at most ``MAX_SEGMENTS`` segments
(:class:`Budget`), so no file can hang the loader or fill the memory.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from insitu.errors import FormatError
from insitu.formats.limits import MAX_DRAWING_BYTES, check_file
from insitu.patterns.model import Pattern

TOL_MM = 0.002
MM_PER_PX = 25.4 / 96.0  # CSS pixel, the SVG user unit
MAX_MM = 1e5      # 100 m: an entity larger than this is a broken file, not a pattern
FAR_MM = 1e9      # coordinates beyond this (1000 km) have lost their precision
PAINT_MODES = ("threshold", "dither")  # how an SVG's shaded paints are marked
BEAM_MM = 0.05    # default beam width: strokes at least this wide are marked as areas
MAX_SEGMENTS = 2_000_000  # flattened segments in one file (a detailed logo has ~1e4)


class Budget:
    """The segments a file may still flatten into; :meth:`take` refuses, naming the entity,
    the first one that would exceed ``limit``."""

    def __init__(self, path: Path, limit: int = MAX_SEGMENTS):
        self.path, self.limit, self.left = path, limit, limit

    def take(self, n: int, what: str) -> None:
        self.left -= n
        if self.left < 0:
            raise FormatError(f"{self.path}: {what}: the drawing flattens to more than "
                              f"{self.limit:,} segments (refused: too detailed to mark)")


def check_finite(pts, path: Path, what: str) -> None:
    """FormatError naming ``what`` when any coordinate of ``pts`` (N, 2 or 3) is not finite
    (checked before flattening: a nan makes curve subdivision run forever)."""
    a = np.asarray(pts, np.float64)
    if not np.isfinite(a).all():
        raise FormatError(f"{path}: {what} has a coordinate that is not a finite number "
                          f"({a[~np.isfinite(a).all(axis=-1)][0].tolist()})")


def bezier_steps(ctrl, tol: float) -> int:
    """Chords of a quadratic (3 control points) or cubic (4) Bézier, uniform in t, so that
    they stay within ``tol`` of the curve (at most 10,000)."""
    c = np.asarray(ctrl, np.float64)
    if len(c) == 3:
        m = float(np.linalg.norm(c[0] - 2 * c[1] + c[2])) / 4.0
    else:
        m = 0.75 * max(float(np.linalg.norm(c[0] - 2 * c[1] + c[2])),
                       float(np.linalg.norm(c[1] - 2 * c[2] + c[3])))
    return max(1, min(10_000, math.ceil(math.sqrt(m / max(tol, 1e-12)))))


def bezier_points(ctrl, tol: float) -> np.ndarray:
    """Points (n+1, 2) along a quadratic (3 control points) or cubic (4) Bézier, from start to
    end inclusive, spaced uniformly in t so the chords stay within ``tol`` of the curve."""
    c = np.asarray(ctrl, np.float64)
    n = bezier_steps(c, tol)
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    s = 1.0 - t
    if len(c) == 3:
        return s * s * c[0] + 2 * s * t * c[1] + t * t * c[2]
    return s**3 * c[0] + 3 * s * s * t * c[1] + 3 * s * t * t * c[2] + t**3 * c[3]


def _arc_steps(radius: float, sweep_rad: float, tol: float) -> int:
    """Chords needed for an arc of ``radius`` so the sagitta stays within ``tol`` and within
    2e-4 · radius (small circles keep their area to 3e-4)."""
    if not (radius > 0 and math.isfinite(radius)):
        return max(1, math.ceil(abs(sweep_rad) / (math.pi / 2)))
    step = 2.0 * math.acos(1.0 - min(tol, 2e-4 * radius) / radius)
    return max(1, min(100_000, math.ceil(abs(sweep_rad) / step)))


def _fail(path: Path, kind: str, e: BaseException) -> FormatError:
    msg = " ".join(str(e).split())[:160] or type(e).__name__
    return FormatError(f"{path}: not a readable {kind} file ({msg})")


def _check_file(path: Path) -> None:
    check_file(path, MAX_DRAWING_BYTES, "drawing", missing="no such pattern file")


def _non_empty(p: Pattern, path: Path, what: str) -> Pattern:
    if p.is_empty:
        raise FormatError(f"{path}: no {what} to mark (empty pattern)")
    return p


def check_extent(pts_mm: np.ndarray, path: Path, what: str) -> None:
    """FormatError naming ``what`` (e.g. "a <rect>", "CIRCLE #2F") when its points (N, 2) mm
    span more than MAX_MM, lie beyond FAR_MM or are not numbers; a small shape far from the
    origin passes (placement moves it)."""
    if not len(pts_mm):
        return
    if not np.isfinite(pts_mm).all() or np.abs(pts_mm).max() > FAR_MM:
        raise FormatError(f"{path}: {what} has coordinates that are not numbers or lie beyond "
                          f"±{FAR_MM:g} mm")
    span = float(np.ptp(pts_mm, axis=0).max())
    if span > MAX_MM:
        raise FormatError(f"{path}: {what} is {span:.4g} mm across (more than {MAX_MM:g} mm)")


def dashed(points, pattern, offset: float = 0.0, closed: bool = False,
           max_dashes: int = 200_000) -> list[np.ndarray]:
    """The pieces (each (n, 2)) of a polyline (N, 2) under a dash ``pattern`` — lengths on,
    off, on, off, … in the points' units (an even count; a dash of length 0 is a dot, a
    one-point piece) — starting ``offset`` into the pattern; a closed polyline is dashed from
    its first point round to it. A line needing more than ``max_dashes`` dashes is returned
    whole (its dashes are finer than anything a beam draws)."""
    p = np.asarray(points, np.float64)[:, :2]
    if closed:
        p = np.vstack([p, p[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    total, pat = float(s[-1]), np.asarray(pattern, np.float64)
    period = float(pat.sum())
    if not (total > 0 and period > 0) or total / period * len(pat) / 2 > max_dashes:
        return [p]
    edges = np.concatenate([[0.0], np.cumsum(pat)])
    first = -(offset % period)
    k = np.arange(math.ceil((total - first) / period) + 1)[:, None] * period + first
    a = (k + edges[0:-1:2][None, :]).ravel()
    b = (k + edges[1::2][None, :]).ravel()
    keep = (b >= 0) & (a <= total) & ((b > a) | (a >= 0))
    out = []
    for lo, hi in zip(np.clip(a[keep], 0, total), np.clip(b[keep], 0, total)):
        inner = np.flatnonzero((s > lo) & (s < hi))
        t = np.concatenate([[lo], s[inner], [hi]]) if hi > lo else np.array([lo])
        out.append(np.column_stack([np.interp(t, s, p[:, 0]), np.interp(t, s, p[:, 1])]))
    return out
