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
