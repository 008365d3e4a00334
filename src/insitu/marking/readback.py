"""Read a marked pattern back from the side camera: rectify the camera's image onto the marked
surface (:mod:`.rectify`), find where the mark lies against the plan, decode its code with
zxing-cpp and grade its print quality (:mod:`insitu.vision.dpm_grade`).

Placement error: the rectified picture, its background removed, is cross-correlated with the
plan drawn in the same frame (the job's paths at the beam's width, :func:`.verify.render`);
the peak (sub-pixel) is the mark's offset from the plan along the pattern's axes u, v, mm on
the surface (wrap: along the surface). Either polarity: dark marks on bright metal or light
on dark. The decoder is handed the picture both ways (zxing-cpp's ``try_invert``).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.geometry.camera import CameraModel
from insitu.marking.project import Projection
from insitu.marking.rectify import MarkFrame, camera_px_per_mm, mark_frame, rectify, surface_points
from insitu.marking.surface import Surface
from insitu.marking.verify import render, unrolled
from insitu.patterns.codes import SYMBOLOGIES
from insitu.patterns.model import Pattern
from insitu.vision.code_decode import read_codes
from insitu.vision.dpm_grade import Grades, grade_symbol

PX_PER_MODULE = 8          # at least this many picture pixels per code module
MARGIN_MODULES = 2         # picture margin beyond a code's quiet zone, modules
MARGIN_MM = 1.0            # … beyond a drawing's bounds, mm
IN_PLACE_MM = 0.5          # a drawing read back within this of its plan is "in place"


@dataclass(frozen=True)
class MarkReading:
    """One mark read back. ``name``: the pattern; ``text``: what its code should read (None:
    not a code); ``decoded``: what the reader read (None: nothing); ``offset_mm``: (u, v) of the
    mark against the plan along the pattern's axes, mm on the surface (None: not found); ``grades``
    of a code's print quality (None: no code, or not found); ``picture`` (H, W) float32 rectified
    grey values (NaN: not seen); ``frame`` its geometry; ``plan`` the pattern's outlines and open
    paths as planned, (N, 2) u, v mm each; ``seen``: share of the mark's frame the camera sees."""

    name: str
    text: str | None
    decoded: str | None
    offset_mm: tuple[float, float] | None
    grades: Grades | None
    picture: np.ndarray
    frame: MarkFrame
    plan: tuple[np.ndarray, ...]
    seen: float

    @property
    def ok(self) -> bool:
        """A code decoded to its planned text (a drawing: found within :data:`IN_PLACE_MM` of
        its plan)."""
        if self.text is not None:
            return self.decoded == self.text
        return self.offset_mm is not None and float(np.hypot(*self.offset_mm)) <= IN_PLACE_MM


def planned_paths(paths3d: list[np.ndarray], projection: Projection) -> list[np.ndarray]:
    """The job's paths (N, 3) back in the pattern plane (N, 2) world mm: their x, y, or
    unrolled along the surface for a projection with an unroll direction (wrap)."""
    if projection.direction_deg is not None and projection.anchor is not None:
        return unrolled(paths3d, projection.anchor, projection.direction_deg)
    return [p[:, :2] for p in paths3d]


def _module_mm(pattern: Pattern) -> float | None:
    if pattern.code is None or pattern.frame is None:
        return None
    f, c = pattern.frame, pattern.code
    return float(np.linalg.norm(f[1] - f[0])) / (c.cols + 2 * c.quiet)


def _highpass(pic: np.ndarray, sigma_px: float) -> np.ndarray:
    """Picture minus its blur (the room light's shading gone), unseen pixels 0."""
    seen = np.isfinite(pic)
    p = np.where(seen, pic, 0).astype(np.float32)
    w = cv2.GaussianBlur(seen.astype(np.float32), (0, 0), sigma_px)
    bg = cv2.GaussianBlur(p, (0, 0), sigma_px) / np.maximum(w, 1e-6)
    return np.where(seen, p - bg, 0).astype(np.float32)


def find_offset(picture: np.ndarray, plan: np.ndarray, max_px: int, sigma_px: float
                ) -> tuple[float, float, float] | None:
    """Shift (dx, dy) px of ``picture`` (H, W, NaN unseen) against ``plan`` (H, W uint8, dark
    marks) at the largest |normalised cross-correlation| within ``max_px``, sub-pixel, and
    that correlation (negative: the marks are light). None when the picture shows nothing."""
    a = _highpass(picture, sigma_px)
    b = _highpass(plan.astype(np.float32), sigma_px)
    if a.std() < 1e-6 or b.std() < 1e-6:
        return None
    pad = max_px
    big = cv2.copyMakeBorder(a, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=0)
    res = cv2.matchTemplate(big, b, cv2.TM_CCORR_NORMED)
    y, x = np.unravel_index(int(np.argmax(np.abs(res))), res.shape)
    m = np.abs(res)

    def sub(v0, vm, vp):
        d = vm - 2 * v0 + vp
        return 0.5 * (vm - vp) / d if d < 0 else 0.0
    dx = x + (sub(m[y, x], m[y, x - 1], m[y, x + 1]) if 0 < x < m.shape[1] - 1 else 0.0)
    dy = y + (sub(m[y, x], m[y - 1, x], m[y + 1, x]) if 0 < y < m.shape[0] - 1 else 0.0)
    return dx - pad, dy - pad, float(res[y, x])


def decode_picture(picture: np.ndarray, symbology: str, module_px: float = 8.0) -> str | None:
    """The text zxing-cpp reads in ``picture`` (NaN: not seen) for ``symbology``, dark or
    light marks, through the ladder of :func:`insitu.vision.code_decode.read_codes` (not
    enlarged: a rectified picture has :data:`PX_PER_MODULE` px a module); None: nothing
    read."""
    found, _ = read_codes(picture, SYMBOLOGIES[symbology][0], module_px, enlarge=False)
    return found[0].text if found else None


def read_mark(image: np.ndarray, camera: CameraModel, surf: Surface, pattern: Pattern,
              projection: Projection, paths3d: list[np.ndarray], beam_mm: float,
              max_offset_mm: float = 1.5) -> MarkReading:
    """Read one mark back from the camera's ``image``: ``pattern`` placed (world x, y before
    projection) and marked as ``paths3d`` (the job's paths of it, (N, 3) mm) by
    ``projection`` on the measured surface ``surf``; ``beam_mm`` the beam's width; the mark
    is looked for within ``max_offset_mm`` of the plan."""
    module = _module_mm(pattern)
    centre = np.array([*pattern.centre, np.nan])
    centre[2] = np.nan_to_num(surf.sample(centre[None, :2]).z[0],
                              nan=float(np.median(surf.points[:, 2])))
    margin = MARGIN_MODULES * module if module is not None else MARGIN_MM
    axes = mark_frame(pattern, margin, 1.0).axes
    px = 1.0 / camera_px_per_mm(camera, centre, axes)
    if module is not None:
        px = min(px, module / PX_PER_MODULE)
    frame = mark_frame(pattern, margin, px)
    points = surface_points(frame, surf, projection)
    picture = rectify(image, camera, points, surf.points, max(surf.spacing_mm, 0.05))
    plan_xy = planned_paths(paths3d, projection)
    outlines = [np.vstack([c, c[:1]]) for c in pattern.contours] + list(pattern.paths)
    plan_uv = tuple(frame.to_uv(p) for p in outlines)
    drawn = render(plan_xy, frame.origin, frame.axes, frame.size_mm, beam_mm, frame.px_mm)
    drawn = drawn[:picture.shape[0], :picture.shape[1]]
    seen = float(np.isfinite(picture).mean())
    sigma = 2.0 * (module or 1.0) / frame.px_mm
    hit = find_offset(picture, drawn, int(np.ceil(max_offset_mm / frame.px_mm)), sigma)
    offset = None if hit is None else (hit[0] * frame.px_mm, -hit[1] * frame.px_mm)
    text = decoded = grades = None
    if pattern.code is not None:
        text = pattern.code.text
        decoded = decode_picture(picture, pattern.code.symbology, module / frame.px_mm)
        if offset is not None:
            grades = _grade(picture, frame, pattern, module, offset, decoded is not None)
    return MarkReading(pattern.name, text, decoded, offset, grades, picture, frame, plan_uv,
                       seen)


def _grade(picture: np.ndarray, frame: MarkFrame, pattern: Pattern, module: float,
           offset: tuple[float, float], decoded: bool) -> Grades:
    """Grade the code of ``pattern`` in its rectified ``picture``, its grid where the plan
    puts it moved by ``offset`` (u, v mm)."""
    import shapely

    c = pattern.code
    q = c.quiet
    # module (row 0 at the top, col 0) centres in pattern-plane world x, y → planned colours
    jj, ii = np.meshgrid(np.arange(c.cols) + 0.5, np.arange(c.rows) + 0.5)
    f0 = pattern.frame[0]
    u_ax, v_ax = frame.axes
    xy = (f0 + ((q + jj) * module)[..., None] * u_ax
          + ((q + c.rows - ii) * module)[..., None] * v_ax)
    matrix = shapely.contains_xy(pattern.to_shapely(), xy[..., 0], xy[..., 1])
    uv00 = frame.to_uv(xy[0, 0][None])[0] + np.asarray(offset)
    centre00 = frame.to_pixels(uv00[None])[0]
    step = module / frame.px_mm
    return grade_symbol(picture, matrix, centre00, np.array([step, 0.0]),
                        np.array([0.0, step]), c.symbology, decoded)
