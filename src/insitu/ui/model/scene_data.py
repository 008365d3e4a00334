"""What the 3-D view draws, as float32 arrays (no Qt, no OpenGL): height colours, outlines,
patterns before and after projection, handles; and the maths of dragging a pattern.
Everything in world mm."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from insitu.errors import InsituError
from insitu.marking import Placement
from insitu.patterns import Pattern, load_pattern
from insitu.patterns.fields import Variables, render_spec

# height colour map stops (t in 0…1 → RGB): blue, cyan, green, yellow, red
COLORMAP_STOPS = np.array([[0.0, 0.15, 0.25, 0.85], [0.25, 0.0, 0.75, 0.9],
                           [0.5, 0.2, 0.8, 0.25], [0.75, 0.95, 0.85, 0.1],
                           [1.0, 0.9, 0.15, 0.1]], np.float32)

FIELD_COLOUR = (0.55, 0.58, 0.62, 1.0)
REGION_COLOUR = (0.95, 0.8, 0.2, 1.0)
PLACED_COLOUR = (0.85, 0.85, 0.95, 0.9)
SELECTED_COLOUR = (1.0, 1.0, 1.0, 1.0)       # white and magenta: apart from the height map
PROJECTED_COLOUR = (1.0, 0.3, 1.0, 1.0)
WARNING_COLOUR = (1.0, 0.15, 0.15, 1.0)
PILOT_COLOUR = (1.0, 0.3, 0.3, 1.0)
SHADE_UNDER_PENS = 0.45  # the cloud's colours dimmed while pens' paths are shown: a pen's
                         # colour stands out from the same hue of the height map (≥ 2:1)
AMBIENT = "ambient"      # cloud attribute: (N,) float32 0…1, the ambient (laser-off) frame's
                         # gray at the pixel each point was measured at (PLY property)
HANDLE_OFFSET_MM = 0.25          # the rotation handle sits this fraction of the height above


def height_colours(z: np.ndarray, z_range: tuple[float, float]) -> np.ndarray:
    """(N,) heights mm → (N, 3) float32 RGB by :data:`COLORMAP_STOPS` over ``z_range``
    (the same map as the point shader)."""
    lo, hi = z_range
    t = np.clip((np.asarray(z, np.float32) - lo) / max(hi - lo, 1e-6), 0, 1)
    s = COLORMAP_STOPS
    return np.stack([np.interp(t, s[:, 0], s[:, c]) for c in (1, 2, 3)], 1).astype(np.float32)


def segments(polylines, z: float | None = None, closed: bool = False) -> np.ndarray:
    """Polylines (N_i, 2 or 3) → (2M, 3) float32 vertex pairs for GL_LINES (``z`` for 2-D
    ones; ``closed`` adds the closing segment)."""
    out = []
    for p in polylines:
        p = np.asarray(p, np.float64)
        if len(p) < 2:
            continue
        if p.shape[1] == 2:
            p = np.c_[p, np.full(len(p), 0.0 if z is None else z)]
        if closed:
            p = np.vstack([p, p[:1]])
        out.append(np.stack([p[:-1], p[1:]], 1).reshape(-1, 3))
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0, 3), np.float32)


def rectangle(x0: float, x1: float, y0: float, y1: float, z: float = 0.0) -> np.ndarray:
    """(8, 3) float32 GL_LINES outline of an axis-aligned rectangle at height ``z``."""
    return segments([np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])], z, closed=True)


def cross(x: float, y: float, z: float, size_mm: float) -> np.ndarray:
    """(12, 3) float32 GL_LINES: a 3-D cross marking a place."""
    c, s = np.array([x, y, z]), size_mm
    axes = np.eye(3) * s
    return np.concatenate([[c - a, c + a] for a in axes]).astype(np.float32)


@lru_cache(maxsize=32)
def base_pattern(spec: str) -> Pattern:
    """The pattern of a file or spec, loaded once (FormatError if it cannot be); variable
    data is drawn with serial 1, the date and time now (a placeholder of its size)."""
    return load_pattern(render_spec(spec, Variables(1)))


def placed_pattern(p: Placement) -> Pattern:
    return base_pattern(p.pattern).placed(p.at_mm, p.width_mm, p.rotate_deg)


def code_hatch(p: Placement) -> tuple[float, float] | None:
    """(spacing mm, angle °) of the hatch along a code placement's modules at its width and
    rotation (``Placement.code_hatch``), None when ``p`` is not a code (or does not load)."""
    try:
        base = base_pattern(p.pattern)
        if base.code is None or base.frame is None:
            return None
        width = base.mark_width if p.width_mm is None else p.width_mm
        return p.code_hatch(base.placed(p.at_mm, width, p.rotate_deg))
    except InsituError:
        return None


def follow_code_hatch(old: Placement, new: Placement) -> Placement:
    """``new`` (``old`` changed), its hatch moved with its modules when ``old``'s hatch ran
    along them (a code's default) and the change did not set the hatch itself: a code made
    wider or turned keeps a whole number of hatch lines per module, along its rows."""
    if (new.hatch_mm, new.hatch_angle_deg) != (old.hatch_mm, old.hatch_angle_deg) \
            or old.hatch_mm is None:
        return new
    before = code_hatch(old)
    if before is None or not (math.isclose(old.hatch_mm, before[0], rel_tol=0, abs_tol=5e-4)
                              and math.isclose(old.hatch_angle_deg, before[1], abs_tol=1e-9)):
        return new
    after = code_hatch(new)
    return new if after is None else replace(new, hatch_mm=after[0], hatch_angle_deg=after[1])


def pattern_lines(pattern: Pattern, z: float) -> np.ndarray:
    """Contours (closed) and paths of a placed pattern as GL_LINES at height ``z``."""
    return np.concatenate([segments(pattern.contours, z, closed=True),
                           segments(pattern.paths, z)])


@dataclass(frozen=True)
class Handles:
    """Screen-independent handle positions of a placement, world (x, y) mm: ``centre``,
    ``rotate`` (above the pattern's top edge) and ``scale`` (its lower right corner)."""

    centre: np.ndarray
    rotate: np.ndarray
    scale: np.ndarray
    corners: np.ndarray          # (4, 2) rotated bounding box


def handles(p: Placement) -> Handles:
    """The handles of placement ``p`` (its rotated, unprojected bounding box)."""
    w, h = base_pattern(p.pattern).size
    h = h * p.width_mm / w if w > 0 else p.width_mm
    w = p.width_mm
    a = math.radians(p.rotate_deg)
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    c = np.asarray(p.at_mm, float)
    local = np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]])
    corners = local @ R.T + c
    rot = c + R @ np.array([0.0, h / 2 + HANDLE_OFFSET_MM * max(h, w)])
    return Handles(c, rot, corners[1], corners)


def rotate_to(p: Placement, mouse_xy) -> float:
    """The rotation (deg, CCW) that puts ``p``'s rotation handle toward ``mouse_xy``."""
    d = np.asarray(mouse_xy, float) - np.asarray(p.at_mm, float)
    return round(math.degrees(math.atan2(d[1], d[0])) - 90.0, 1) % 360.0


def scale_to(p: Placement, start_width_mm: float, start_xy, mouse_xy) -> float:
    """The width (mm) that scales ``p`` by how far the mouse moved from its centre
    (distance now / distance at the start of the drag), at least 0.1 mm."""
    c = np.asarray(p.at_mm, float)
    d0 = np.linalg.norm(np.asarray(start_xy, float) - c)
    d1 = np.linalg.norm(np.asarray(mouse_xy, float) - c)
    return max(round(start_width_mm * d1 / max(d0, 1e-6), 2), 0.1)


def pattern_at(items, xy) -> int:
    """The index of the last of placements ``items`` whose rotated box holds ``xy`` mm
    (drawn on top), or -1."""
    from shapely import Point, Polygon

    for i in range(len(items) - 1, -1, -1):
        try:
            corners = handles(items[i]).corners
        except InsituError:
            continue
        if Polygon(corners).covers(Point(*xy)):
            return i
    return -1


def pattern_in_box(items, box) -> int:
    """The index of the placement of ``items`` whose centre lies in ``box`` (x0, x1, y0, y1)
    mm — of several, the one nearest the box's centre — or -1 (nothing selected)."""
    x0, x1, y0, y1 = box
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    inside = [(float(np.hypot(*(np.asarray(p.at_mm) - centre))), i)
              for i, p in enumerate(items)
              if x0 <= p.at_mm[0] <= x1 and y0 <= p.at_mm[1] <= y1]
    return min(inside)[1] if inside else -1
