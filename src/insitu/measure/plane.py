"""Method 1 of Li et al. (§2.1, Eqs. 2–4): intersect camera rays with the light plane that the
scan head's geometry defines (pivot a = (0, 0, H) and the commanded segment b–c)."""

from __future__ import annotations

import numpy as np

from insitu.geometry.beams import light_plane
from insitu.geometry.camera import CameraModel


def intersect_plane(camera: CameraModel, uv: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """(N, 2) distorted pixels → (N, 3) world points on ``plane`` [A, B, C, D] (world frame).

    Solves Eq. 3 in the world frame: the ray C + s·d meets A x + B y + C z + D = 0. Rays
    (nearly) parallel to the plane give NaN.
    """
    origin, dirs = camera.rays(uv)
    n, D = plane[:3], plane[3]
    denom = dirs @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -(origin @ n + D) / denom
    s[np.abs(denom) < 1e-9] = np.nan
    return origin + s[:, None] * dirs


def reconstruct_line(camera: CameraModel, uv: np.ndarray, start, end,
                     pivot_height_mm: float, telecentric: bool = False) -> np.ndarray:
    """Method 1 for one frame: centres (N, 2) px of the line start → end → (N, 3) points, mm."""
    return intersect_plane(camera, uv, light_plane(pivot_height_mm, start, end, telecentric))


def expected_band(camera: CameraModel, start, end, pivot_height_mm: float,
                  z_range_mm: tuple[float, float], margin_px: float = 25.0,
                  telecentric: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Rows (v_lo, v_hi), each (W,), where the line start → end can appear in the image for
    surfaces within ``z_range_mm``: its light plane between the two heights, projected, plus a
    margin for the head's distortion and calibration errors. NaN: columns it cannot reach."""
    plane = light_plane(pivot_height_mm, start, end, telecentric)
    s = np.linspace(0.0, 1.0, 64)[:, None]
    xy = (1 - s) * np.asarray(start, float) + s * np.asarray(end, float)
    rows = []
    for z in z_range_mm:
        # points of the plane at height z above the commanded segment: solve the plane for x
        # (lines along y) or y (lines along x), whichever the plane's normal allows
        p = np.column_stack([xy, np.full(len(xy), float(z))])
        axis = 0 if abs(plane[0]) >= abs(plane[1]) else 1
        other = 1 - axis
        p[:, axis] = -(plane[other] * p[:, other] + plane[2] * z + plane[3]) / plane[axis]
        rows.append(camera.project(p))
    uv = np.vstack(rows)
    uv = uv[np.isfinite(uv).all(axis=1)]
    W = camera.width
    lo, hi = np.full(W, np.nan), np.full(W, np.nan)
    if len(uv) < 4:
        return lo, hi
    a, b = rows[0], rows[1]
    order_a, order_b = np.argsort(a[:, 0]), np.argsort(b[:, 0])
    u = np.arange(W, dtype=np.float64)
    va = np.interp(u, a[order_a, 0], a[order_a, 1], left=np.nan, right=np.nan)
    vb = np.interp(u, b[order_b, 0], b[order_b, 1], left=np.nan, right=np.nan)
    umin = min(a[:, 0].min(), b[:, 0].min()) - margin_px
    umax = max(a[:, 0].max(), b[:, 0].max()) + margin_px
    inside = (u >= umin) & (u <= umax)
    va = np.interp(u, u[np.isfinite(va)], va[np.isfinite(va)]) if np.isfinite(va).any() else va
    vb = np.interp(u, u[np.isfinite(vb)], vb[np.isfinite(vb)]) if np.isfinite(vb).any() else vb
    lo = np.where(inside, np.minimum(va, vb) - margin_px, np.nan)
    hi = np.where(inside, np.maximum(va, vb) + margin_px, np.nan)
    return lo, hi
