"""Scan-field correction: a smooth model of where the beam lands, and its inverse.

Convention (ours; Mikkelstrup et al. Eq. 6 write δ with the opposite sign): a command C on
z = 0 lands at ``landing(C) = C + δ(C)`` — δ = P − Q for a measured spot P of command Q, mm.
Two models of δ:

* :class:`RBFNetwork` — Mikkelstrup et al. §2.7: Gaussian neurons ``exp(-|x - c|² / 2σ²)``,
  2 outputs plus bias, centres picked among the training points by orthogonal least squares
  forward selection (Chen, Cowan & Grant 1991) until the MSE goal is met; σ and the goal
  chosen by 5-fold cross-validation over a small grid (:func:`select_rbf`).
* :class:`CorrectionTable` — Le & Quinsat §6: δ on a regular grid of nodes over the whole
  field, interpolated by the bicubic (not-a-knot) spline through the nodes; the node values
  are fitted to the scattered measurements by least squares with a second-difference
  smoothness penalty (which also fills nodes without data); the penalty by 5-fold CV
  (:func:`select_table`).

Correction (§2.8, iterated): the command for target Q is the K with ``K + δ(K) = Q``, found by
Newton steps (:func:`invert`) — K = Q − δ(Q) is only its first step. All arrays (N, 2), mm.
"""

from __future__ import annotations

import ctypes
import importlib.util
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.interpolate import make_interp_spline

from insitu.errors import CalibrationError

Model = Callable[[np.ndarray], np.ndarray]
MIN_POINTS = 10


# -- BLAS threads ----------------------------------------------------------------------------
@lru_cache(maxsize=1)
def _openblas_local_setters() -> tuple:
    """``openblas_set_num_threads_local`` of the OpenBLAS copies numpy and scipy load."""
    found = []
    for pkg in ("numpy", "scipy"):
        try:
            root = Path(importlib.util.find_spec(pkg).origin).parent.parent / f"{pkg}.libs"
            for lib in root.glob("*openblas*.so*"):
                fn = getattr(ctypes.CDLL(str(lib)), "openblas_set_num_threads_local", None)
                if fn is not None:
                    fn.restype, fn.argtypes = ctypes.c_int, [ctypes.c_int]
                    found.append(fn)
        except (OSError, AttributeError, TypeError):
            continue
    return tuple(found)


@contextmanager
def single_threaded_blas():
    """Run the calling thread's BLAS on one thread. Our matrices are small (≤ ~600): BLAS
    threads only spin against each other, and on a busy machine that makes the fits 5–30×
    slower. Affects the calling thread only; a no-op where OpenBLAS is not found."""
    setters = _openblas_local_setters()
    previous = [fn(1) for fn in setters]
    try:
        yield
    finally:
        for fn, n in zip(setters, previous):
            fn(max(int(n), 1))


# -- RBF network ---------------------------------------------------------------------------
@dataclass(frozen=True)
class RBFNetwork:
    """g(x) = Σ_j w_j exp(-|x - c_j|² / 2σ²) + b. centres (m, 2) mm, weights (m, 2) mm,
    bias (2,) mm, sigma mm."""

    centres: np.ndarray
    weights: np.ndarray
    bias: np.ndarray
    sigma: float

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        return _gauss(xy, self.centres, self.sigma) @ self.weights + self.bias


def _gauss(x: np.ndarray, c: np.ndarray, sigma: float) -> np.ndarray:
    d2 = (x[:, None, 0] - c[None, :, 0]) ** 2 + (x[:, None, 1] - c[None, :, 1]) ** 2
    return np.exp(-d2 / (2.0 * sigma * sigma))


def ols_order(X: np.ndarray, D: np.ndarray, sigma: float, mse_goal: float,
              max_neurons: int | None = None, min_norm: float = 1e-9
              ) -> tuple[list[int], list[float]]:
    """Orthogonal least squares forward selection (Chen et al. 1991, multi-output).

    Candidates: Gaussians at every training point X (N, 2); targets D (N, 2). The bias is
    taken first, then at each step the candidate with the largest error reduction
    Σ_k (pᵀd_k)² / pᵀp (p: the candidate orthogonalised on those chosen). Stops when the
    training MSE (mean over N × 2) reaches ``mse_goal``, at ``max_neurons`` (default N / 2),
    or when no candidate is left independent (orthogonalised norm² below ``min_norm`` of its
    own). Returns the chosen indices and the MSE after each.
    """
    P = _gauss(X, X, sigma)
    P -= P.mean(axis=0)                       # orthogonal to the bias column
    R = D - D.mean(axis=0)
    norms0 = np.einsum("ij,ij->j", P, P) + 1e-300
    free = np.ones(len(X), bool)
    order, mse = [], []
    limit = len(X) // 2 if max_neurons is None else min(max_neurons, len(X))
    while len(order) < limit and float(np.mean(R * R)) > mse_goal:
        norms = np.einsum("ij,ij->j", P, P)
        ok = free & (norms > min_norm * norms0)
        if not ok.any():
            break
        proj = P.T @ R                          # (M, 2)
        gain = np.where(ok, (proj * proj).sum(1) / np.where(ok, norms, 1.0), -1.0)
        j = int(np.argmax(gain))
        p = P[:, j].copy()
        R -= np.outer(p, proj[j] / norms[j])
        P -= np.outer(p, (p @ P) / norms[j])
        free[j] = False
        order.append(j)
        mse.append(float(np.mean(R * R)))
    return order, mse


def fit_rbf(X: np.ndarray, D: np.ndarray, sigma: float, mse_goal: float,
            max_neurons: int | None = None, order: Sequence[int] | None = None) -> RBFNetwork:
    """The network on the OLS-selected centres (or ``order``), weights and bias by least
    squares on the training points X (N, 2) → D (N, 2)."""
    X, D = np.asarray(X, np.float64), np.asarray(D, np.float64)
    if order is None:
        order, _ = ols_order(X, D, sigma, mse_goal, max_neurons)
    c = X[list(order)]
    A = np.column_stack([_gauss(X, c, sigma), np.ones(len(X))])
    sol, *_ = np.linalg.lstsq(A, D, rcond=None)
    return RBFNetwork(c, sol[:-1], sol[-1], float(sigma))


# -- correction table ----------------------------------------------------------------------
@dataclass(frozen=True)
class CorrectionTable:
    """δ at the grid nodes: x_nodes (nx,), y_nodes (ny,) increasing, mm; values (ny, nx, 2)
    mm. Between nodes: the bicubic not-a-knot spline through them (as
    scipy.interpolate.RectBivariateSpline with s = 0)."""

    x_nodes: np.ndarray
    y_nodes: np.ndarray
    values: np.ndarray
    smoothing: float = 0.0

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        Lx, Ly = _cardinal(self.x_nodes, xy[:, 0]), _cardinal(self.y_nodes, xy[:, 1])
        return np.einsum("ni,nj,jik->nk", Lx, Ly, self.values)


def _cardinal(nodes: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(N, n): the 1-D interpolating cubic splines through unit values at each node."""
    n = len(nodes)
    k = 3 if n >= 4 else n - 1
    return make_interp_spline(nodes, np.eye(n), k=k)(x)


@lru_cache(maxsize=8)
def _penalty(nx: int, ny: int) -> np.ndarray:
    """LᵀL of the second differences of (ny·nx) node values (index j·nx + i): d²/dx²,
    d²/dy² and √2·d²/dxdy stencils, i.e. a discrete thin-plate energy."""
    idx = np.arange(nx * ny).reshape(ny, nx)
    s = np.sqrt(2.0)
    stencils = [(idx[:, :-2], idx[:, 1:-1], idx[:, 2:], None, (1.0, -2.0, 1.0)),
                (idx[:-2], idx[1:-1], idx[2:], None, (1.0, -2.0, 1.0)),
                (idx[:-1, :-1], idx[1:, 1:], idx[:-1, 1:], idx[1:, :-1], (s, s, -s, -s))]
    blocks = []
    for *cols, weights in stencils:
        cols = [c.ravel() for c in cols if c is not None]
        L = np.zeros((len(cols[0]), nx * ny))
        rows = np.arange(len(cols[0]))
        for c, w in zip(cols, weights):
            np.add.at(L, (rows, c), w)
        blocks.append(L)
    L = np.vstack(blocks)
    return L.T @ L


def _design(X: np.ndarray, xn: np.ndarray, yn: np.ndarray) -> np.ndarray:
    """(N, ny·nx): the table's value at X as a linear function of the node values."""
    Lx, Ly = _cardinal(xn, X[:, 0]), _cardinal(yn, X[:, 1])
    return (Ly[:, :, None] * Lx[:, None, :]).reshape(len(X), -1)


def fit_table(X: np.ndarray, D: np.ndarray, x_nodes: np.ndarray, y_nodes: np.ndarray,
              smoothing: float | Sequence[float]) -> CorrectionTable | list[CorrectionTable]:
    """Node values minimising Σ|table(X) − D|² + λ·(N / nodes)·|second differences|², with
    λ = ``smoothing`` (dimensionless); several λ give several tables (one factorisation)."""
    X, D = np.asarray(X, np.float64), np.asarray(D, np.float64)
    xn, yn = np.asarray(x_nodes, np.float64), np.asarray(y_nodes, np.float64)
    A = _design(X, xn, yn)
    AtA, AtD, P = A.T @ A, A.T @ D, _penalty(len(xn), len(yn))
    out = []
    for lam in np.atleast_1d(smoothing):
        M = AtA + float(lam) * len(X) / A.shape[1] * P + 1e-12 * np.eye(A.shape[1])
        V = np.linalg.solve(M, AtD)
        out.append(CorrectionTable(xn, yn, V.reshape(len(yn), len(xn), 2), float(lam)))
    return out if np.ndim(smoothing) else out[0]


def table_nodes(extent: Sequence[float], X: np.ndarray, pitch_mm: float | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Nodes over ``extent`` (x0, x1, y0, y1), mm, at ``pitch_mm`` (default: the mean spacing
    of the measured points), at least 4 per side."""
    x0, x1, y0, y1 = map(float, extent)
    if pitch_mm is None:
        pitch_mm = float(np.sqrt(np.ptp(X[:, 0]) * np.ptp(X[:, 1]) / len(X))) or 10.0
    nx = max(int(round((x1 - x0) / pitch_mm)) + 1, 4)
    ny = max(int(round((y1 - y0) / pitch_mm)) + 1, 4)
    return np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)


# -- cross-validation and selection ----------------------------------------------------------
@dataclass(frozen=True)
class CVResult:
    """k-fold CV of one setting: per-fold RMS of |δ̂ − δ| on held-out points (mm) and the
    out-of-fold residuals (N, 2), mm."""

    params: dict
    fold_rms: np.ndarray
    residuals: np.ndarray

    rms = property(lambda self: float(np.sqrt(np.mean(np.sum(self.residuals**2, 1)))))
    max = property(lambda self: float(np.linalg.norm(self.residuals, axis=1).max()))
    mean_fold_rms = property(lambda self: float(self.fold_rms.mean()))
    std_fold_rms = property(lambda self: float(self.fold_rms.std()))


def folds(n: int, k: int = 5, seed: int = 0) -> list[np.ndarray]:
    """k disjoint index sets covering range(n), shuffled with ``seed``."""
    idx = np.random.default_rng(seed).permutation(n)
    return [np.sort(idx[i::k]) for i in range(k)]


def _cv(X, D, k, fit_many: Callable[[np.ndarray, np.ndarray], list[tuple[dict, Model]]]
        ) -> list[CVResult]:
    """CV for several settings at once: ``fit_many(Xtrain, Dtrain)`` → [(params, model)]."""
    res, per = None, None
    for f, test in enumerate(folds(len(X), k)):
        train = np.setdiff1d(np.arange(len(X)), test)
        models = fit_many(X[train], D[train])
        if res is None:
            res = [np.zeros_like(D) for _ in models]
            per = np.zeros((len(models), k))
        for m, (_, model) in enumerate(models):
            r = model(X[test]) - D[test]
            res[m][test] = r
            per[m, f] = np.sqrt(np.mean(np.sum(r**2, 1)))
    return [CVResult(params, per[m], res[m]) for m, (params, _) in enumerate(models)]


def default_sigmas(X: np.ndarray) -> list[float]:
    """Spreads to try, mm: 0.15 … 0.75 of the half extent of the points."""
    half = 0.5 * max(np.ptp(X[:, 0]), np.ptp(X[:, 1]), 1e-9)
    return [float(round(half * f, 1)) for f in (0.15, 0.25, 0.35, 0.5, 0.75)]


DEFAULT_GOALS = (1e-5, 3e-5, 1e-4, 3e-4, 1e-3)      # mm², mean over both outputs
DEFAULT_SMOOTHING = (1e-4, 1e-3, 1e-2, 1e-1, 1.0)


@dataclass(frozen=True)
class Selection:
    """The chosen model, its CV and the CV of every setting tried (best first)."""

    model: Model
    cv: CVResult
    tried: list[CVResult] = field(default_factory=list)


def select_rbf(X: np.ndarray, D: np.ndarray, sigmas: Sequence[float] | None = None,
               goals: Sequence[float] = DEFAULT_GOALS, k: int = 5,
               max_neurons: int | None = None) -> Selection:
    """σ and MSE goal by k-fold CV (smallest held-out RMS), then the network on all points.
    One OLS run per σ and fold serves every goal (the selection is nested)."""
    X, D = _check_points(X, D)
    sigmas = list(sigmas) if sigmas is not None else default_sigmas(X)
    goals = sorted(goals)

    def fit_many(Xt, Dt):
        out = []
        for s in sigmas:
            order, mse = ols_order(Xt, Dt, s, goals[0], max_neurons)
            for g in goals:
                m = next((i + 1 for i, e in enumerate(mse) if e <= g), len(order))
                out.append(({"sigma_mm": s, "mse_goal_mm2": g},
                            fit_rbf(Xt, Dt, s, g, order=order[:m])))
        return out

    with single_threaded_blas():
        tried = sorted(_cv(X, D, k, fit_many), key=lambda c: c.rms)
        best = tried[0]
        model = fit_rbf(X, D, best.params["sigma_mm"], best.params["mse_goal_mm2"], max_neurons)
    return Selection(model, best, tried)


def select_table(X: np.ndarray, D: np.ndarray, extent: Sequence[float],
                 smoothing: Sequence[float] = DEFAULT_SMOOTHING, k: int = 5,
                 pitches_mm: Sequence[float] | None = None) -> Selection:
    """Node pitch and smoothing by k-fold CV, then the table over ``extent`` on all points.
    Pitches default to 1, 1.5 and 2 × the mean spacing of the points."""
    X, D = _check_points(X, D)
    if pitches_mm is None:
        spacing = float(np.sqrt(np.ptp(X[:, 0]) * np.ptp(X[:, 1]) / len(X))) or 10.0
        pitches_mm = [round(spacing * f, 2) for f in (1.0, 1.5, 2.0)]
    grids = {float(p): table_nodes(extent, X, p) for p in pitches_mm}

    def fit_many(Xt, Dt):
        return [({"pitch_mm": p, "smoothing": t.smoothing}, t) for p, (xn, yn) in grids.items()
                for t in fit_table(Xt, Dt, xn, yn, smoothing)]

    with single_threaded_blas():
        tried = sorted(_cv(X, D, k, fit_many), key=lambda c: c.rms)
        best = tried[0]
        xn, yn = grids[best.params["pitch_mm"]]
        model = fit_table(X, D, xn, yn, best.params["smoothing"])
    return Selection(model, best, tried)


def _check_points(X, D) -> tuple[np.ndarray, np.ndarray]:
    X, D = np.asarray(X, np.float64).reshape(-1, 2), np.asarray(D, np.float64).reshape(-1, 2)
    if len(X) != len(D):
        raise ValueError(f"{len(X)} points but {len(D)} deviations")
    if len(X) < MIN_POINTS:
        raise CalibrationError(f"too few measured spots for a field correction: {len(X)} "
                               f"(need at least {MIN_POINTS})")
    if not (np.isfinite(X).all() and np.isfinite(D).all()):
        raise CalibrationError("the measured spots contain non-finite values")
    return X, D


# -- correction ----------------------------------------------------------------------------
def invert(delta: Model, targets: np.ndarray, tol_mm: float = 1e-7, max_iter: int = 30,
           step_mm: float = 1e-3) -> np.ndarray:
    """Commands K (N, 2) with K + δ(K) = targets (N, 2), mm: Newton's method with a central
    finite-difference Jacobian, from K = Q − δ(Q). CalibrationError if it does not converge
    (the modelled field folds over: a bad correction)."""
    Q = np.asarray(targets, np.float64).reshape(-1, 2)
    K = Q - delta(Q)
    ex, ey = np.array([step_mm, 0.0]), np.array([0.0, step_mm])
    for _ in range(max_iter):
        r = K + delta(K) - Q
        if not np.isfinite(r).all():
            break
        if np.abs(r).max() <= tol_mm:
            return K
        J = np.empty((len(K), 2, 2))
        J[:, :, 0] = (delta(K + ex) - delta(K - ex)) / (2 * step_mm)
        J[:, :, 1] = (delta(K + ey) - delta(K - ey)) / (2 * step_mm)
        J += np.eye(2)
        K = K - np.linalg.solve(J, r[:, :, None])[:, :, 0]
    r = K + delta(K) - Q
    if np.isfinite(r).all() and np.abs(r).max() <= max(tol_mm, 1e-5):
        return K
    bad_ = int(np.nanargmax(np.where(np.isfinite(r), np.abs(r), np.inf).max(1)))
    raise CalibrationError(f"the field correction does not converge for target "
                           f"{Q[bad_].round(4).tolist()} mm (the modelled field folds over)")
