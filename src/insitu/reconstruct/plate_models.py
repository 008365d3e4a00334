"""The height models of Method 2 as a scan evaluates them — fitted on a flat plate recorded
at known heights with lines at known offsets (:mod:`insitu.calibrate.height_fit`).

* :class:`PaperHeightModel` — exactly the paper: P = P1 + P2 (Eq. 6) with average pixel
  distances to the reference line (offset 0, height 0); P1(x) by linear interpolation, Z from
  (x, P2) by interpolation on the calibration grid (Fig. 3). X, Y: the camera ray at that Z.
* :class:`SheetHeightModel` — ours: every centre of every calibration frame is the camera ray
  meeting the plate at its known height, so the frames trace where each light sheet really
  is. A smooth model X = X_pivot(x, Y, Z) + δX(x, Y, Z) of all sheets (the pivot model plus a
  polynomial correction in the commanded offset x, Y and Z) absorbs the head's distortion,
  the pivot-height error and the camera's errors; a scan point is the camera ray meeting its
  sheet (Newton on the ray, started from Method 1).

Both take lines along y (constant x), as the paper does; both are a
:class:`~insitu.reconstruct.height_models.HeightModel`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

from insitu.errors import MeasurementError
from insitu.geometry.beams import light_plane
from insitu.geometry.camera import CameraModel

SCALE_MM = np.array([100.0, 100.0, 25.0])   # x, Y, Z normalisation, mm


def ray_at_height(camera: CameraModel, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(N, 3) world mm where the camera rays of pixels ``uv`` (N, 2) reach heights ``z`` (N,)."""
    origin, d = camera.rays(uv)
    s = (z - origin[2]) / d[:, 2]
    return origin + s[:, None] * d


@dataclass(frozen=True)
class PaperHeightModel:
    """Li et al.'s P = P1 + P2. ``ref_u``, ``ref_v``: the reference line's centres (offset 0,
    height 0); ``offsets`` (K,), ``heights`` (J,) and ``P`` (K, J) average pixel distances."""

    ref_u: np.ndarray
    ref_v: np.ndarray
    offsets: np.ndarray
    heights: np.ndarray
    P: np.ndarray

    name = "paper"

    @property
    def z_range(self) -> tuple[float, float]:
        """The plate heights of the calibration grid, (low, high) mm."""
        return float(self.heights.min()), float(self.heights.max())

    def height(self, x_mm: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Z (N,) mm of centres (u, v) of the line at offset x. NaN outside the reference."""
        p = v - np.interp(u, self.ref_u, self.ref_v, left=np.nan, right=np.nan)
        j0 = int(np.searchsorted(self.heights, 0.0))
        P1 = self.P[:, j0] if self.heights[j0] == 0.0 else np.array(
            [np.interp(0.0, self.heights, row) for row in self.P])
        p2 = p - np.interp(x_mm, self.offsets, P1)
        # Z(P2) at each calibrated offset, then linear interpolation across the offset x
        k = int(np.clip(np.searchsorted(self.offsets, x_mm) - 1, 0, len(self.offsets) - 2))
        zs = []
        for kk in (k, k + 1):
            p2_grid = self.P[kk] - P1[kk]
            order = np.argsort(p2_grid)
            zs.append(_interp_extrap(p2, p2_grid[order], self.heights[order]))
        w = (x_mm - self.offsets[k]) / (self.offsets[k + 1] - self.offsets[k])
        return (1 - w) * zs[0] + w * zs[1]

    def points(self, camera: CameraModel, x_mm: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        z = self.height(x_mm, u, v)
        return ray_at_height(camera, np.column_stack([u, v]), z)

    def to_dict(self) -> dict:
        return {"ref_u": self.ref_u.tolist(), "ref_v": self.ref_v.tolist(),
                "offsets_mm": self.offsets.tolist(), "heights_mm": self.heights.tolist(),
                "P_px": self.P.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "PaperHeightModel":
        return cls(np.array(d["ref_u"]), np.array(d["ref_v"]), np.array(d["offsets_mm"]),
                   np.array(d["heights_mm"]), np.array(d["P_px"]))


def _interp_extrap(x, xp, fp):
    """Linear interpolation that extends the end segments (a little beyond the grid)."""
    y = np.interp(x, xp, fp)
    lo, hi = x < xp[0], x > xp[-1]
    y[lo] = fp[0] + (x[lo] - xp[0]) * (fp[1] - fp[0]) / (xp[1] - xp[0])
    y[hi] = fp[-1] + (x[hi] - xp[-1]) * (fp[-1] - fp[-2]) / (xp[-1] - xp[-2])
    return y


# -- our model ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class SheetHeightModel:
    """All light sheets as X = x (H − Z) / H + δX(x, Y, Z); δX a polynomial (``exps`` (M, 3),
    ``coef`` (M,) mm) in x/100, Y/100, Z/25 mm. ``H``: the nominal pivot height."""

    H: float
    exps: np.ndarray
    coef: np.ndarray
    x_range: tuple[float, float]
    z_range: tuple[float, float]

    name = "sheet"

    def _frame_poly(self, x_mm: float) -> np.ndarray:
        """δX for the line at offset x as a 2-D coefficient array over (Y/100, Z/25)."""
        deg = self.exps.max(axis=0)
        C = np.zeros((deg[1] + 1, deg[2] + 1))
        xa = (x_mm / SCALE_MM[0]) ** self.exps[:, 0]
        np.add.at(C, (self.exps[:, 1], self.exps[:, 2]), self.coef * xa)
        return C

    def sheet_x(self, x_mm: float, Y: np.ndarray, Z: np.ndarray) -> np.ndarray:
        """X (N,) of the sheet of the line at offset x at (Y, Z), mm."""
        C = self._frame_poly(x_mm)
        return x_mm * (self.H - Z) / self.H + P.polyval2d(Y / SCALE_MM[1], Z / SCALE_MM[2], C)

    def points(self, camera: CameraModel, x_mm: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(N, 3) world points of centres (u, v) of the line at offset x: each camera ray meets
        the sheet (Newton along the ray from the nominal light plane; 4 steps reach < 1e-9 mm)."""
        uv = np.column_stack([u, v])
        origin, d = camera.rays(uv)
        C = self._frame_poly(x_mm)
        CY, CZ = P.polyder(C, axis=0) / SCALE_MM[1], P.polyder(C, axis=1) / SCALE_MM[2]
        plane = light_plane(self.H, [x_mm, -1.0], [x_mm, 1.0])
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -(origin @ plane[:3] + plane[3]) / (d @ plane[:3])
            for _ in range(4):
                p = origin + s[:, None] * d
                y, z = p[:, 1] / SCALE_MM[1], p[:, 2] / SCALE_MM[2]
                f = p[:, 0] - x_mm * (self.H - p[:, 2]) / self.H - P.polyval2d(y, z, C)
                df = (d[:, 0] + x_mm * d[:, 2] / self.H
                      - P.polyval2d(y, z, CY) * d[:, 1] - P.polyval2d(y, z, CZ) * d[:, 2])
                s = s - f / df
        return origin + s[:, None] * d

    def to_dict(self) -> dict:
        return {"pivot_height_mm": self.H, "exponents": self.exps.tolist(),
                "coefficients_mm": self.coef.tolist(), "scale_mm": SCALE_MM.tolist(),
                "x_range_mm": list(self.x_range), "z_range_mm": list(self.z_range)}

    @classmethod
    def from_dict(cls, d: dict) -> "SheetHeightModel":
        return cls(float(d["pivot_height_mm"]), np.array(d["exponents"], dtype=np.int64),
                   np.array(d["coefficients_mm"]), tuple(d["x_range_mm"]), tuple(d["z_range_mm"]))


STRAY = 0.001
"""Share of a scan's points that may lie outside the calibrated heights as strays (a ghost's
streak; dropped): more is a part the calibration does not reach (refused)."""


def check_bracket(model, z: np.ndarray, what: str, tol_mm: float = 2.0,
                  stray: float = STRAY) -> np.ndarray:
    """Which heights z (N,) lie within the heights the calibration recorded (± ``tol_mm``);
    MeasurementError when more than the share ``stray`` of them do not."""
    lo, hi = model.z_range
    inside = ~np.isfinite(z) | ((z >= lo - tol_mm) & (z <= hi + tol_mm))
    if (~inside).sum() > stray * len(z):
        zf = z[np.isfinite(z)]
        raise MeasurementError(f"{what}: measured heights {zf.min():.1f} … {zf.max():.1f} mm are "
                               f"outside the height calibration's {lo:g} … {hi:g} mm")
    return inside


