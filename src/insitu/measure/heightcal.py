"""Height calibration (Li et al. §2.2) from a flat plate recorded at known heights with lines
at known offsets, and the better model of ours that uses every centre's row and column.

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
:class:`~insitu.measure.height_models.HeightModel`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

from insitu.errors import CalibrationError, MeasurementError
from insitu.geometry.camera import CameraModel
from insitu.geometry.beams import light_plane

_SCALE = np.array([100.0, 100.0, 25.0])   # x, Y, Z normalisation, mm


@dataclass(frozen=True)
class LineObservation:
    """Centres of one calibration frame: the line at offset ``x_mm`` on the plate at ``z_mm``."""

    x_mm: float
    z_mm: float
    u: np.ndarray
    v: np.ndarray


def _ray_at_height(camera: CameraModel, uv: np.ndarray, z: np.ndarray) -> np.ndarray:
    origin, d = camera.rays(uv)
    s = (z - origin[2]) / d[:, 2]
    return origin + s[:, None] * d


# -- the paper's model ------------------------------------------------------------------------
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

    @classmethod
    def fit(cls, obs: list[LineObservation]) -> "PaperHeightModel":
        offsets = np.unique([o.x_mm for o in obs])
        heights = np.unique([o.z_mm for o in obs])
        ref = [o for o in obs if o.x_mm == 0.0 and o.z_mm == 0.0]
        if not ref:
            raise CalibrationError("height calibration: the paper's method needs the reference "
                                   "line (offset 0 mm on the plate at height 0 mm)")
        ref_u, ref_v = ref[0].u, ref[0].v
        P = np.full((len(offsets), len(heights)), np.nan)
        for o in obs:
            d = o.v - np.interp(o.u, ref_u, ref_v, left=np.nan, right=np.nan)
            if np.isfinite(d).sum() >= 5:
                P[np.searchsorted(offsets, o.x_mm), np.searchsorted(heights, o.z_mm)] = np.nanmean(d)
        if np.isnan(P).any():
            k, j = np.argwhere(np.isnan(P))[0]
            raise CalibrationError(f"height calibration: no line seen at offset {offsets[k]:g} mm "
                                   f"on the plate at {heights[j]:g} mm")
        return cls(ref_u, ref_v, offsets, heights, P)

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
        return _ray_at_height(camera, np.column_stack([u, v]), z)

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
def _exponents(deg_x: int, deg_y: int, deg_z: int, total: int) -> np.ndarray:
    """(M, 3) exponents (a, b, c) of x^a Y^b Z^c with a ≤ deg_x, b ≤ deg_y, c ≤ deg_z and
    a + b + c ≤ total, in np.polynomial.polyvander3d's column order."""
    e = [(a, b, c) for a in range(deg_x + 1) for b in range(deg_y + 1) for c in range(deg_z + 1)]
    return np.array([t for t in e if sum(t) <= total], dtype=np.int64)


def _design(exps: np.ndarray, x: np.ndarray, Y: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """(N, M) monomials of the normalised (x, Y, Z)."""
    deg = exps.max(axis=0)
    V = P.polyvander3d(np.broadcast_to(x, Y.shape) / _SCALE[0], Y / _SCALE[1], Z / _SCALE[2], deg)
    cols = (exps[:, 0] * (deg[1] + 1) + exps[:, 1]) * (deg[2] + 1) + exps[:, 2]
    return V[:, cols]


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

    @classmethod
    def fit(cls, obs: list[LineObservation], camera: CameraModel, pivot_height_mm: float,
            degrees=(3, 4, 2), total: int = 6) -> "SheetHeightModel":
        xs, pts = [], []
        for o in obs:
            pts.append(_ray_at_height(camera, np.column_stack([o.u, o.v]), np.full(len(o.u), o.z_mm)))
            xs.append(np.full(len(o.u), o.x_mm))
        x, p = np.concatenate(xs), np.concatenate(pts)
        X, Y, Z = p.T
        exps = _exponents(*degrees, total)
        if len(np.unique(x)) < 2 or len(np.unique(Z)) < 2 or len(x) < 4 * len(exps):
            raise CalibrationError("height calibration: needs lines at two or more offsets on "
                                   "the plate at two or more heights")
        H = float(pivot_height_mm)
        resid = X - x * (H - Z) / H
        A = _design(exps, x, Y, Z)
        keep = np.ones(len(x), bool)
        for _ in range(3):  # drop gross outliers (ghost centres) and refit
            coef = np.linalg.lstsq(A[keep], resid[keep], rcond=None)[0]
            r = A @ coef - resid
            keep = np.abs(r) < max(6 * 1.4826 * np.median(np.abs(r[keep])), 1e-3)
        return cls(H, exps, coef, (float(x.min()), float(x.max())), (float(Z.min()), float(Z.max())))

    def _frame_poly(self, x_mm: float) -> np.ndarray:
        """δX for the line at offset x as a 2-D coefficient array over (Y/100, Z/25)."""
        deg = self.exps.max(axis=0)
        C = np.zeros((deg[1] + 1, deg[2] + 1))
        xa = (x_mm / _SCALE[0]) ** self.exps[:, 0]
        np.add.at(C, (self.exps[:, 1], self.exps[:, 2]), self.coef * xa)
        return C

    def sheet_x(self, x_mm: float, Y: np.ndarray, Z: np.ndarray) -> np.ndarray:
        """X (N,) of the sheet of the line at offset x at (Y, Z), mm."""
        C = self._frame_poly(x_mm)
        return x_mm * (self.H - Z) / self.H + P.polyval2d(Y / _SCALE[1], Z / _SCALE[2], C)

    def points(self, camera: CameraModel, x_mm: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """(N, 3) world points of centres (u, v) of the line at offset x: each camera ray meets
        the sheet (Newton along the ray from the nominal light plane; 4 steps reach < 1e-9 mm)."""
        uv = np.column_stack([u, v])
        origin, d = camera.rays(uv)
        C = self._frame_poly(x_mm)
        CY, CZ = P.polyder(C, axis=0) / _SCALE[1], P.polyder(C, axis=1) / _SCALE[2]
        plane = light_plane(self.H, [x_mm, -1.0], [x_mm, 1.0])
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -(origin @ plane[:3] + plane[3]) / (d @ plane[:3])
            for _ in range(4):
                p = origin + s[:, None] * d
                y, z = p[:, 1] / _SCALE[1], p[:, 2] / _SCALE[2]
                f = p[:, 0] - x_mm * (self.H - p[:, 2]) / self.H - P.polyval2d(y, z, C)
                df = (d[:, 0] + x_mm * d[:, 2] / self.H
                      - P.polyval2d(y, z, CY) * d[:, 1] - P.polyval2d(y, z, CZ) * d[:, 2])
                s = s - f / df
        return origin + s[:, None] * d

    def to_dict(self) -> dict:
        return {"pivot_height_mm": self.H, "exponents": self.exps.tolist(),
                "coefficients_mm": self.coef.tolist(), "scale_mm": _SCALE.tolist(),
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


def height_residuals(model, camera: CameraModel, obs: list[LineObservation]) -> dict[str, float]:
    """Height error of ``model`` on calibration frames: RMS and max |Z − plate height|, mm."""
    err = np.concatenate([model.points(camera, o.x_mm, o.u, o.v)[:, 2] - o.z_mm for o in obs])
    err = err[np.isfinite(err)]
    return {"rms_mm": float(np.sqrt(np.mean(err**2))), "max_mm": float(np.max(np.abs(err))),
            "points": float(len(err))}


def residual_grid(model, camera: CameraModel, obs: list[LineObservation]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the calibration is good: plate heights (H,) and line offsets (X,), mm, and the
    RMS of |Z − plate height| (H, X), mm, of the frame at each (NaN where there is none)."""
    heights = np.unique([o.z_mm for o in obs])
    offsets = np.unique([o.x_mm for o in obs])
    sq = np.zeros((len(heights), len(offsets)))
    n = np.zeros_like(sq)
    for o in obs:
        e = model.points(camera, o.x_mm, o.u, o.v)[:, 2] - o.z_mm
        e = e[np.isfinite(e)]
        i, j = np.searchsorted(heights, o.z_mm), np.searchsorted(offsets, o.x_mm)
        sq[i, j] += float(np.sum(e * e))
        n[i, j] += len(e)
    with np.errstate(invalid="ignore", divide="ignore"):
        return heights, offsets, np.where(n > 0, np.sqrt(sq / n), np.nan)


def cross_validate_sheet(obs: list[LineObservation], camera: CameraModel,
                         pivot_height_mm: float) -> dict[str, float]:
    """Leave-one-height-out: fit without each plate height, test on it (needs ≥ 3 heights)."""
    heights = np.unique([o.z_mm for o in obs])
    errs = []
    for z in heights[1:-1]:  # interpolation only: the end heights would be extrapolation
        model = SheetHeightModel.fit([o for o in obs if o.z_mm != z], camera, pivot_height_mm)
        test = [o for o in obs if o.z_mm == z]
        errs.append(np.concatenate([model.points(camera, o.x_mm, o.u, o.v)[:, 2] - z for o in test]))
    if not errs:
        return {}
    e = np.concatenate(errs)
    e = e[np.isfinite(e)]
    return {"cv_rms_mm": float(np.sqrt(np.mean(e**2))), "cv_max_mm": float(np.max(np.abs(e)))}
