"""The 3-D view's guides as plain maths (no Qt, no OpenGL): the mm grid on z = 0 with a
spacing that follows the zoom (1, 2 or 5 × 10^k mm), the ticks of the rulers along the
view's edges, the scale bar and the x/y/z axes. Everything in world mm or widget pixels."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from insitu.ui.model.orbit_camera import OrbitCamera

GRID_MIN_PX = 24             # minor grid lines at least this far apart on screen
RULER_MIN_PX = 60            # labelled ruler ticks at least this far apart
SCALE_BAR_PX = 120           # the scale bar is at most this long
AXIS_PX = 70                 # the axes at the origin are about this long on screen
GRID_LINES_MAX = 200         # per direction (a far perspective horizon is cut off)


def nice_step(min_mm: float) -> float:
    """The smallest 1, 2 or 5 × 10^k mm that is at least ``min_mm`` (> 0)."""
    k = math.floor(math.log10(max(min_mm, 1e-9)))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10.0 ** k >= min_mm * (1 - 1e-9):
            return m * 10.0 ** k
    return 10.0 ** (k + 1)


def nice_floor(max_mm: float) -> float:
    """The largest 1, 2 or 5 × 10^k mm that is at most ``max_mm`` (> 0)."""
    k = math.floor(math.log10(max(max_mm, 1e-9)))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** k <= max_mm * (1 + 1e-9):
            return m * 10.0 ** k
    return 10.0 ** k


def major_every(step_mm: float) -> int:
    """Minor lines per major one, so that major lines fall on multiples of 10^(k+1) mm:
    10 for a 1 × 10^k step, 5 for 2 × 10^k, 2 for 5 × 10^k."""
    mantissa = round(step_mm / 10.0 ** math.floor(math.log10(step_mm) + 1e-9))
    return {1: 10, 2: 5, 5: 2}.get(mantissa, 10)


@dataclass(frozen=True)
class Grid:
    """``minor`` and ``major``: (2M, 3) float32 GL_LINES on z = 0; ``step_mm``: spacing."""

    step_mm: float
    minor: np.ndarray
    major: np.ndarray


def visible_plane_box(cam: OrbitCamera, width: int, height: int, z_mm: float = 0.0
                      ) -> tuple[float, float, float, float] | None:
    """(x0, x1, y0, y1) mm of the plane z = ``z_mm`` seen in the view (its edge pixels'
    rays; a horizon cut off at :data:`GRID_LINES_MAX` steps), None when it is not seen."""
    t = np.linspace(0, 1, 9)
    edge = np.concatenate([np.c_[t * width, np.zeros(9)], np.c_[t * width, np.full(9, height)],
                           np.c_[np.zeros(9), t * height], np.c_[np.full(9, width), t * height],
                           [[width / 2, height / 2]]])
    hit = cam.pick_planes(edge, width, height, z_mm)
    hit = hit[~np.isnan(hit).any(1)]
    if len(hit) == 0:
        return None
    lim = GRID_LINES_MAX * cam.mm_per_px(height) * GRID_MIN_PX / 2
    c = np.asarray(cam.centre, float)[:2]
    lo = np.maximum(hit[:, :2].min(0), c - lim)
    hi = np.minimum(hit[:, :2].max(0), c + lim)
    if (hi < lo).any():
        return None
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def grid(cam: OrbitCamera, width: int, height: int) -> Grid:
    """The grid on z = 0 over what the view shows, ``step_mm`` the nice step that puts minor
    lines at least :data:`GRID_MIN_PX` apart at the view's centre."""
    step = nice_step(cam.mm_per_px(height) * GRID_MIN_PX)
    box = visible_plane_box(cam, width, height)
    empty = np.zeros((0, 3), np.float32)
    if box is None:
        return Grid(step, empty, empty)
    x0, x1, y0, y1 = box
    every = major_every(step)
    minor, major = [], []
    for axis, (a0, a1), (b0, b1) in ((0, (x0, x1), (y0, y1)), (1, (y0, y1), (x0, x1))):
        for k in range(math.ceil(a0 / step), math.floor(a1 / step) + 1):
            seg = [[k * step, b0, 0.0], [k * step, b1, 0.0]] if axis == 0 else \
                  [[b0, k * step, 0.0], [b1, k * step, 0.0]]
            (major if k % every == 0 else minor).append(seg)
    as_lines = (lambda s: np.asarray(s, np.float32).reshape(-1, 3) if s else empty)
    return Grid(step, as_lines(minor), as_lines(major))


@dataclass(frozen=True)
class Ruler:
    """Labelled ticks along one edge of the view: ``edge`` ("bottom" or "left"), ``axis``
    (0 = x, 1 = y: the world coordinate it measures), ``positions_px`` (K,) along the edge,
    ``values_mm`` (K,)."""

    edge: str
    axis: int
    positions_px: np.ndarray
    values_mm: np.ndarray


def rulers(cam: OrbitCamera, width: int, height: int, inset_px: float = 0.0) -> list[Ruler]:
    """The bottom and left rulers: where the plane z = 0 seen along each edge crosses
    multiples of a nice step of the coordinate (x or y) that changes most along it."""
    out = []
    for edge in ("bottom", "left"):
        n = max(int((width if edge == "bottom" else height) / 2), 2)
        t = np.linspace(0, width if edge == "bottom" else height, n)
        px = np.c_[t, np.full(n, height - inset_px)] if edge == "bottom" else \
            np.c_[np.full(n, inset_px), t]
        hit = cam.pick_planes(px, width, height)[:, :2]
        ok = ~np.isnan(hit).any(1)
        if ok.sum() < 2:
            continue
        span = np.nanmax(hit[ok], 0) - np.nanmin(hit[ok], 0)
        axis = int(np.argmax(span))
        v = hit[:, axis]
        mm_per_px = span[axis] / max(abs(t[ok][-1] - t[ok][0]), 1)
        step = nice_step(mm_per_px * RULER_MIN_PX)
        k = np.floor(v / step)
        cross = np.nonzero(ok[:-1] & ok[1:] & (k[:-1] != k[1:]))[0]
        edges_mm = np.maximum(k[cross], k[cross + 1]) * step
        frac = (edges_mm - v[cross]) / (v[cross + 1] - v[cross])
        out.append(Ruler(edge, axis, t[cross] + frac * (t[cross + 1] - t[cross]), edges_mm))
    return out


def scale_bar(cam: OrbitCamera, height: int) -> tuple[float, float]:
    """(length mm, length px) of the scale bar: the largest nice length that is at most
    :data:`SCALE_BAR_PX` long at the view's centre."""
    mm_per_px = cam.mm_per_px(height)
    mm = nice_floor(mm_per_px * SCALE_BAR_PX)
    return mm, mm / mm_per_px


def axes(cam: OrbitCamera, height: int) -> tuple[float, np.ndarray]:
    """(length mm, (6, 3) float32 GL_LINES x, y, z from the origin): a nice length of about
    :data:`AXIS_PX` on screen."""
    length = nice_step(cam.mm_per_px(height) * AXIS_PX)
    tips = np.eye(3) * length
    return length, np.concatenate([[np.zeros(3), tip] for tip in tips]).astype(np.float32)
