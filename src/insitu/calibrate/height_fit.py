"""Fitting the height models (Li et al. §2.2 and ours) to a flat plate recorded at known
heights with lines at known offsets (:class:`LineObservation` per frame), and how well they
fit: residuals per height and offset, leave-one-height-out cross-validation. The models
themselves, as a scan evaluates them, are :mod:`insitu.reconstruct.plate_models`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

from insitu.errors import CalibrationError
from insitu.geometry.camera import CameraModel
from insitu.reconstruct.plate_models import (
    SCALE_MM,
    PaperHeightModel,
    SheetHeightModel,
    ray_at_height,
)
from insitu.reconstruct.turned_sheet import TurnedSheetModel, turned_camera


@dataclass(frozen=True)
class LineObservation:
    """Centres of one calibration frame: the line at offset ``x_mm`` on the plate at ``z_mm``."""

    x_mm: float
    z_mm: float
    u: np.ndarray
    v: np.ndarray


def fit_paper(obs: list[LineObservation]) -> PaperHeightModel:
    """Li et al.'s P1 + P2 (Eq. 6) from the calibration frames; CalibrationError without the
    reference line (offset 0 on the plate at height 0) or with a grid cell that has no line."""
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
    return PaperHeightModel(ref_u, ref_v, offsets, heights, P)


def _exponents(deg_x: int, deg_y: int, deg_z: int, total: int) -> np.ndarray:
    """(M, 3) exponents (a, b, c) of x^a Y^b Z^c with a ≤ deg_x, b ≤ deg_y, c ≤ deg_z and
    a + b + c ≤ total, in np.polynomial.polyvander3d's column order."""
    e = [(a, b, c) for a in range(deg_x + 1) for b in range(deg_y + 1) for c in range(deg_z + 1)]
    return np.array([t for t in e if sum(t) <= total], dtype=np.int64)


def _design(exps: np.ndarray, x: np.ndarray, Y: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """(N, M) monomials of the normalised (x, Y, Z)."""
    deg = exps.max(axis=0)
    V = P.polyvander3d(np.broadcast_to(x, Y.shape) / SCALE_MM[0], Y / SCALE_MM[1], Z / SCALE_MM[2], deg)
    cols = (exps[:, 0] * (deg[1] + 1) + exps[:, 1]) * (deg[2] + 1) + exps[:, 2]
    return V[:, cols]


def fit_sheet(obs: list[LineObservation], camera: CameraModel, pivot_height_mm: float,
              degrees=(3, 4, 2), total: int = 6) -> SheetHeightModel:
    """Our sheet model: every centre is its camera ray meeting the plate at its known height;
    δX a polynomial (``degrees`` in x, Y, Z, ``total`` at most) fitted by least squares with
    gross outliers (ghost centres) dropped. CalibrationError with fewer than two offsets or
    heights."""
    xs, pts = [], []
    for o in obs:
        pts.append(ray_at_height(camera, np.column_stack([o.u, o.v]), np.full(len(o.u), o.z_mm)))
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
    return SheetHeightModel(H, exps, coef, (float(x.min()), float(x.max())), (float(Z.min()), float(Z.max())))


def fit_turned_sheet(obs: list[LineObservation], camera: CameraModel, pivot_height_mm: float,
                     angle_deg: float) -> TurnedSheetModel:
    """The crossed pass's model: ``obs`` the crossed frames, each ``x_mm`` its turned offset
    (:func:`insitu.reconstruct.turned_sheet.turned_offset`)."""
    cam = turned_camera(camera, angle_deg)
    return TurnedSheetModel(float(angle_deg), fit_sheet(obs, cam, pivot_height_mm))


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
        model = fit_sheet([o for o in obs if o.z_mm != z], camera, pivot_height_mm)
        test = [o for o in obs if o.z_mm == z]
        errs.append(np.concatenate([model.points(camera, o.x_mm, o.u, o.v)[:, 2] - z for o in test]))
    if not errs:
        return {}
    e = np.concatenate(errs)
    e = e[np.isfinite(e)]
    return {"cv_rms_mm": float(np.sqrt(np.mean(e**2))), "cv_max_mm": float(np.max(np.abs(e)))}
