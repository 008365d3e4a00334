"""Method 1 of Li et al. (§2.1, Eqs. 2–4): intersect camera rays with the light plane that the
scan head's geometry defines (pivot a = (0, 0, H) and the commanded segment b–c)."""

from __future__ import annotations

import numpy as np

from insitu.geometry.beams import light_plane
from insitu.geometry.camera import CameraModel
from insitu.reconstruct.band_kernel import band_edges, plane_points


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


def line_runs_along_rows(camera: CameraModel, start, end) -> bool:
    """True when the commanded line crosses more image columns than rows (seen on z = 0)."""
    uv = camera.project(np.array([[start[0], start[1], 0.0], [end[0], end[1], 0.0]]))
    du, dv = np.abs(uv[1] - uv[0])
    return bool(du >= dv)


def expected_band(camera: CameraModel, start, end, pivot_height_mm: float,
                  z_range_mm: tuple[float, float], margin_px: float = 25.0,
                  telecentric: bool = False, along_rows: bool = True
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Where the line start → end can appear in the image for surfaces within ``z_range_mm``:
    its light plane between the two heights, projected, plus a margin for the head's
    distortion and calibration errors. ``along_rows``: the line crosses the columns, and the
    band is rows (lo, hi) per column, each (W,); else columns per row, each (H,). NaN where
    the line cannot be."""
    lo, hi, _ = band_and_side(camera, start, end, pivot_height_mm, z_range_mm, margin_px,
                              telecentric, along_rows)
    return lo, hi


_S = np.linspace(-0.05, 1.05, 96)
_ALONG = np.stack((1 - _S, _S))
"""The 96 points along the line, 5 % beyond each end, :func:`band_and_side` projects: the
weights of its start and its end, (2, 96)."""


def band_and_side(camera: CameraModel, start, end, pivot_height_mm: float,
                  z_range_mm: tuple[float, float], margin_px: float = 25.0,
                  telecentric: bool = False, along_rows: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`expected_band` (lo, hi), and which way a higher surface moves the line across
    itself in the image: +1 to larger rows (columns when not ``along_rows``), −1 to
    smaller, 0 where it cannot be told (the line outside the image)."""
    return _band(camera, start, end, pivot_height_mm, z_range_mm, margin_px, telecentric,
                 along_rows)[1:]


def line_band(camera: CameraModel, start, end, pivot_height_mm: float,
              z_range_mm: tuple[float, float], margin_px: float = 25.0,
              telecentric: bool = False) -> tuple[bool, np.ndarray, np.ndarray, int]:
    """(along_rows, lo, hi, side): :func:`line_runs_along_rows` and :func:`band_and_side` of
    the line in one projection (the line's ends on z = 0 projected with the band's points);
    the same values as the two calls."""
    return _band(camera, start, end, pivot_height_mm, z_range_mm, margin_px, telecentric,
                 None)


def _band(camera, start, end, pivot_height_mm, z_range_mm, margin_px, telecentric,
          along_rows):
    """(along_rows, lo, hi, side); ``along_rows`` None: decided from the same projection
    (:func:`~insitu.reconstruct.band_kernel.plane_points`,
    :func:`~insitu.reconstruct.band_kernel.band_edges`)."""
    plane = light_plane(pivot_height_mm, start, end, telecentric)
    axis = 0 if abs(plane[0]) >= abs(plane[1]) else 1      # solve the plane for x or for y
    p = plane_points(np.asarray(start, np.float64), np.asarray(end, np.float64), plane,
                     np.asarray(z_range_mm, np.float64), _ALONG, axis)
    if along_rows is None:                                         # the ends on z = 0
        pix = camera.project(p)
        du, dv = np.abs(pix[-1] - pix[-2])
        along_rows, pix = bool(du >= dv), pix[:-2]
    else:
        pix = camera.project(p[:-2])
    along, across = (0, 1) if along_rows else (1, 0)
    n = camera.width if along_rows else camera.height
    edges = []
    for uv in pix.reshape(2, -1, 2):
        uv = uv[np.isfinite(uv).all(axis=1)]
        if len(uv) < 2:
            return along_rows, np.full(n, np.nan), np.full(n, np.nan), 0
        o = np.argsort(uv[:, along])
        edges += [uv[o, along], uv[o, across]]
    lo, hi, side = band_edges(*edges, n, float(np.sign(z_range_mm[1] - z_range_mm[0])),
                              float(margin_px))
    return along_rows, lo, hi, side
