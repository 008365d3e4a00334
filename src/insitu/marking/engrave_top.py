"""The top around a pocket, from the scan's points on it: a plane (its tilt) plus per-line
offsets, a quadratic only where its curvature is significant, and the standard error of the
top where the floor is (:func:`insitu.marking.engrave_depth.measure_depth` uses it).

A plane, not a quadratic, unless the top's curvature shows: fitted to a ring round a hole,
a quadratic's three extra terms carry the top's noise into the hole's middle (on the
simulated plate its pocket depths scatter 2 × as far as with a plane)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.stats import f as f_dist

CURVED_P = 1e-3
"""The F-test's level at which the top is taken as curved (a quadratic)."""


@dataclass(frozen=True)
class TopModel:
    """The top fitted: ``basis`` (N, 2+) points → (N, P) terms, ``coef`` (P,), ``offsets``
    (line number → mm), ``cov`` (P, P) the coefficients' covariance (lines independent, a
    line's points not), ``rms`` mm the residual rms."""

    basis: Callable[[np.ndarray], np.ndarray]
    coef: np.ndarray
    offsets: dict
    cov: np.ndarray
    rms: float

    def at(self, q: np.ndarray, q_line: np.ndarray) -> np.ndarray:
        """(N,) the top's z (mm) at points ``q`` (N, 2+) of lines ``q_line`` (N,)."""
        off = np.array([self.offsets.get(k, 0.0) for k in np.asarray(q_line).tolist()])
        return self.basis(q) @ self.coef + off

    def sem(self, q: np.ndarray) -> float:
        """The standard error (mm) of the top's mean over points ``q`` (N, 2+)."""
        a = self.basis(q).mean(0)
        return float(np.sqrt(max(a @ self.cov @ a, 0.0)))


def top_model(p: np.ndarray, line: np.ndarray) -> TopModel:
    """Fit the top's points ``p`` (N, 3) mm of scan lines ``line`` (N,): a plane plus per-line
    offsets shrunk by their evidence (a random effect), a quadratic where its three extra
    terms lower the residuals beyond chance (F-test at :data:`CURVED_P`)."""
    c0, scale = p[:, :2].mean(0), np.maximum(p[:, :2].std(0), 1e-6)

    def quadratic(q):
        u, v = ((q[:, :2] - c0) / scale).T
        return np.column_stack([np.ones(len(q)), u, v, u * u, u * v, v * v])

    def plane(q):
        return quadratic(q)[:, :3]

    lines, inv = np.unique(line, return_inverse=True)
    basis, fit = plane, top_fit(plane(p), p[:, 2], inv, len(lines))
    res, keep = fit[2], fit[3]
    n = int(keep.sum())
    if n > 12:
        z = p[keep, 2] - fit[1][inv[keep]]
        rss_q = np.linalg.lstsq(quadratic(p[keep]), z, rcond=None)[1]
        rss_p = float((res[keep] ** 2).sum())
        if len(rss_q) and (rss_p - rss_q[0]) / 3 > f_dist.ppf(1 - CURVED_P, 3, n - 6) * (
                rss_q[0] / (n - 6)):
            basis, fit = quadratic, top_fit(quadratic(p), p[:, 2], inv, len(lines))
    coef, b, res, keep = fit
    A = basis(p[keep])
    bread = np.linalg.pinv(A.T @ A)
    g = np.zeros((len(lines), A.shape[1]))
    np.add.at(g, inv[keep], A * res[keep, None])
    cov = bread @ (g.T @ g) @ bread
    return TopModel(basis, coef, dict(zip(lines.tolist(), b)), cov,
                    float(np.sqrt(np.mean(res[keep] ** 2))))


def top_fit(A: np.ndarray, z: np.ndarray, inv: np.ndarray, n_lines: int):
    """Least squares of ``z`` (N,) on ``A`` (N, P) plus line offsets (``inv`` (N,): 0 …
    n_lines − 1) shrunk by their evidence, points beyond 4σ left out: (coef, offsets,
    residuals, kept). A line mean's noise is the points' variance over their number, not
    their MAD's: the centres' errors are heavy-tailed (kurtosis 4–8 on the simulated
    plate), and with the MAD the noise alone passed for offsets of 4–8 µm rms."""
    keep = np.ones(len(z), bool)
    offset = np.zeros(len(z))
    for _ in range(3):
        coef = np.linalg.lstsq(A[keep], (z - offset)[keep], rcond=None)[0]
        r = z - A @ coef
        n = np.bincount(inv[keep], minlength=n_lines).astype(float)
        mean = np.bincount(inv[keep], r[keep], minlength=n_lines) / np.maximum(n, 1)
        within = np.sqrt(np.mean((r[keep] - mean[inv[keep]]) ** 2))
        noise = within ** 2 / np.maximum(n, 1)
        between = max(np.var(mean[n > 0]) - np.mean(noise[n > 0]), 0.0)
        b = np.where(n > 0, mean * between / (between + noise), 0.0)
        offset = b[inv]
        res = z - A @ coef - offset
        keep = np.abs(res) <= 4 * max(np.median(np.abs(res)) * 1.4826, 1e-6)
    return coef, b, res, keep
