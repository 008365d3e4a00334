"""Safety checks before any job exists: a pattern outside the scan field or the focus range,
over a hole in the cloud or over a wall steeper than a limit is refused with a SafetyError
that names the place (x, y mm) and the reason. Nothing here fires or moves anything.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.errors import SafetyError
from insitu.geometry.beams import TwoMirrorHead
from insitu.geometry.field import check_in_field
from insitu.marking.project import Projection

DEFAULT_MAX_SLOPE_DEG = 60.0


@dataclass(frozen=True)
class Limits:
    """Where the head may mark. ``field_size_mm``: usable field on z = 0, centred on the
    origin; ``z_range_mm``: focus range (world z); ``max_slope_deg``: steepest surface to mark;
    ``head``: nominal kinematics — when given, a target's field position is where its beam
    crosses z = 0 (what the mirrors must reach), else its own x, y."""

    field_size_mm: tuple[float, float] = (200.0, 200.0)
    z_range_mm: tuple[float, float] = (-25.0, 25.0)
    max_slope_deg: float = DEFAULT_MAX_SLOPE_DEG
    head: TwoMirrorHead | None = None

    @classmethod
    def of(cls, head_config, max_slope_deg: float = DEFAULT_MAX_SLOPE_DEG) -> "Limits":
        """From the scan head's geometry (a :class:`~insitu.formats.rig.ScanHeadGeometry`)."""
        return cls(tuple(head_config.field_size_mm), tuple(head_config.z_range_mm),
                   max_slope_deg, TwoMirrorHead.of(head_config))


def _where(p: np.ndarray) -> str:
    return f"({p[0]:.3f}, {p[1]:.3f}) mm"


def point_name(pts: np.ndarray, i: int) -> str:
    """How a refusal names target ``i`` of ``pts`` (N, ≥ 2) world mm."""
    return f"pattern point at (x, y) = {_where(pts[i])}"


def _refuse(bad: np.ndarray, pts: np.ndarray, what, worst: int | None = None) -> None:
    """SafetyError naming the point ``worst`` (default: the first bad one) and ``what`` is
    wrong there (a string, or a function of the point's index); ``where_mm``: its x, y."""
    idx = np.flatnonzero(bad)
    i = int(idx[0] if worst is None else worst)
    more = f" (and {len(idx) - 1} more points)" if len(idx) > 1 else ""
    reason = what(i) if callable(what) else what
    raise SafetyError(f"{point_name(pts, i)} {reason}{more}", where_mm=pts[i, :2])


def field_positions(points: np.ndarray, head: TwoMirrorHead | None) -> np.ndarray:
    """(N, 3) targets → (N, 2) where their nominal beams cross z = 0 (x, y if no head)."""
    if head is None:
        return points[:, :2]
    ax, ay, _ = head.inverse(points[:, 0], points[:, 1], points[:, 2])
    x, y = head.forward(2 * ax, 2 * ay, 0.0)
    return np.column_stack([x, y])


def check_targets(points: np.ndarray, limits: Limits) -> None:
    """Every (N, 3) target finite, inside the field and the focus range; else SafetyError."""
    pts = np.asarray(points, float).reshape(-1, 3)
    if len(pts) == 0:
        return
    bad = ~np.isfinite(pts).all(1)
    if bad.any():
        _refuse(bad, np.nan_to_num(pts), "has no height (not on the measured surface)")
    fp = field_positions(pts, limits.head)
    check_in_field(fp, limits.field_size_mm, lambda i, field: f"{point_name(pts, i)} (z = "
                   f"{pts[i, 2]:.3f} mm) is outside the scan field {field} (beam at "
                   f"{_where(fp[i])} on z = 0)", at=pts, worst=True, more=True)
    z0, z1 = limits.z_range_mm
    out = (pts[:, 2] < z0) | (pts[:, 2] > z1)
    if out.any():
        worst = int(np.argmax(np.maximum(z0 - pts[:, 2], pts[:, 2] - z1)))
        _refuse(out, pts, lambda i: f"at height z = {pts[i, 2]:.3f} mm is outside the focus "
                f"range {z0:g} … {z1:g} mm", worst)


def check_projection(proj: Projection, limits: Limits) -> None:
    """Refuse (SafetyError) a projected pattern over a hole in the cloud (no measured point
    within the hole radius), over a wall steeper than ``limits.max_slope_deg``, or with any
    point outside the field or the focus range. Returns None when all is well."""
    pts = proj.points
    if len(pts) == 0:
        return
    check_in_field(pts[:, :2], limits.field_size_mm, lambda i, field: f"{point_name(pts, i)} "
                   f"is outside the scan field {field}", more=True)
    hole = ~(proj.gap_mm <= proj.hole_radius_mm) | ~np.isfinite(pts[:, 2])
    if hole.any():
        _refuse(hole, pts, f"is over a hole in the point cloud (no measured point within "
                f"{proj.hole_radius_mm:.2f} mm; a hole, a shadow or outside the scanned area)")
    steep = proj.slope_deg > limits.max_slope_deg
    if steep.any():
        worst = int(np.argmax(np.where(steep, proj.slope_deg, -1)))
        _refuse(steep, pts, lambda i: f"is over a wall steeper than {limits.max_slope_deg:g}° "
                f"(local surface slope {proj.slope_deg[i]:.1f}°)", worst)
    check_targets(pts, limits)
