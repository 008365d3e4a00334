"""Steger's Hessian ridge detector (Steger 1998, "An unbiased detector of curvilinear
structures"), evaluated only in a small patch around each column's detected peak.

Per column: Gaussian derivatives (pixel-integrated kernels, scale sigma) at the 7 rows around
the peak; the eigenvector of the Hessian with the most negative eigenvalue λ is the line
normal n; t = -(n·∇I)/(nᵀHn) is the sub-pixel offset; a pixel is a line pixel when
|t·n_u|, |t·n_v| ≤ 0.5 px and -λ ≥ min_curvature. The strongest line pixel of the column is
then refined to the crossing of the column itself: the root of n·∇I along v, from a cubic
Hermite interpolation of n·∇I and its v-derivative n·H·e_v between two rows (removes the
Taylor step's O(t³/σ²) bias). Tilted lines are fine: the profile along the column is a
stretched copy of the line's normal profile.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.special import ndtr

from insitu.vision.centres import (LineCentres, _as_image, _detect, _fwhm, _gather,
                                   _plateau_centre, _saturation)

_M = 3          # candidate rows: the detected peak ± _M
_T_MAX = 0.6    # |t·n| ≤ 0.5 px, plus room for the Taylor step's overshoot near pixel borders


def gaussian_kernels(sigma: float, radius: int):
    """Correlation kernels (2·radius+1,) float32 of the pixel-integrated Gaussian and its first
    and second derivative, normalised so that they are exact on constants, ramps, parabolas."""
    x = np.arange(-radius, radius + 1, dtype=np.float64)

    def phi(t):
        return np.exp(-t * t / (2 * sigma**2)) / (np.sqrt(2 * np.pi) * sigma)

    h0 = ndtr((x + 0.5) / sigma) - ndtr((x - 0.5) / sigma)
    h1 = phi(x - 0.5) - phi(x + 0.5)
    h2 = -(x + 0.5) / sigma**2 * phi(x + 0.5) + (x - 0.5) / sigma**2 * phi(x - 0.5)
    h0 /= h0.sum()
    h1 /= (x * h1).sum()
    h2 -= h2.mean()
    h2 /= (x * x * h2).sum() / 2
    return h0.astype(np.float32), h1.astype(np.float32), h2.astype(np.float32)


def _hermite_root(y0, d0, y1, d1):
    """Root s in [0, 1] of the cubic Hermite interpolant of (y0, d0) at 0 and (y1, d1) at 1."""
    s = np.clip(y0 / np.where(y0 != y1, y0 - y1, 1.0), 0.0, 1.0)
    for _ in range(4):
        s2, s3 = s * s, s * s * s
        p = (2 * s3 - 3 * s2 + 1) * y0 + (s3 - 2 * s2 + s) * d0 + (3 * s2 - 2 * s3) * y1 + (s3 - s2) * d1
        dp = (6 * s2 - 6 * s) * (y0 - y1) + (3 * s2 - 4 * s + 1) * d0 + (3 * s2 - 2 * s) * d1
        s = np.clip(s - p / np.where(np.abs(dp) > 1e-12, dp, 1e-12), 0.0, 1.0)
    return s


def steger(image: np.ndarray, sigma: float | None = None, min_peak: float = 40.0,
           window: int = 12, median: int = 3, *, band=None, min_contrast: float = 20.0,
           snr: float = 6.0, continuity: bool = True, saturation: float | None = None,
           min_curvature: float | None = None) -> LineCentres:
    """Steger centres of a line running (roughly, tilts ≲ 60° fine) along the rows of ``image``.

    image: (H, W) uint8/uint16/float32. sigma: Gaussian scale, px (None: from the line's
    median FWHM, σ = max(1, FWHM / (2√3)), Steger's σ ≥ w/√3 for a bar of half-width w).
    min_curvature: least -λ, gray values/px² (None: 0.1 · min_contrast / σ²). Other arguments
    as :func:`insitu.vision.centres.gray_centroid`; detection, band and continuity are shared.
    u is the column for refined points, else c + t·n_u. width: FWHM px of the filtered column.
    """
    img = _as_image(image)
    det = _detect(img, median, band, window, min_peak, min_contrast, snr, continuity)
    c, r, n = det.cols, det.row, len(det.cols)
    H, W = img.shape
    w = max(int(window), 3)
    g, inside = _gather(det.pre, r[None, :] + np.arange(-w, w + 1)[:, None], c)
    width = _fwhm(g, inside, det.bg, det.gmax)
    if sigma is None:
        sigma = max(1.0, float(np.median(width)) / (2 * np.sqrt(3))) if n else 1.0
    if min_curvature is None:
        min_curvature = 0.1 * min_contrast / sigma**2
    R = int(np.ceil(3.5 * sigma))
    h0, h1, h2 = gaussian_kernels(sigma, R)
    M = _M + 1
    rows = np.clip(r[:, None, None] + np.arange(-M - R, M + R + 1)[None, :, None], 0, H - 1)
    cols = np.clip(c[:, None, None] + np.arange(-R, R + 1)[None, None, :], 0, W - 1)
    P = img[rows, cols].astype(np.float32)                        # (n, 2M+2R+1, 2R+1)
    A0, A1, A2 = P @ h0, P @ h1, P @ h2                           # along u: (n, 2M+2R+1)

    def along_v(a, h):                                            # → (n, 2M+1) rows r-M..r+M
        return sliding_window_view(a, 2 * R + 1, axis=1) @ h

    Iu, Iv = along_v(A1, h0), along_v(A0, h1)
    Iuu, Ivv, Iuv = along_v(A2, h0), along_v(A0, h2), along_v(A1, h1)
    half = (Iuu + Ivv) / 2
    root = np.sqrt(((Iuu - Ivv) / 2) ** 2 + Iuv**2)
    lam = half - root                                             # most negative eigenvalue
    e1u, e1v, e2u, e2v = Iuv, lam - Iuu, lam - Ivv, Iuv
    first = e1u**2 + e1v**2 >= e2u**2 + e2v**2
    nu, nv = np.where(first, e1u, e2u), np.where(first, e1v, e2v)
    norm = np.hypot(nu, nv)
    flat = norm < 1e-12
    nu, nv = np.where(flat, 0.0, nu / np.where(flat, 1, norm)), np.where(flat, 1.0, nv / np.where(flat, 1, norm))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -(nu * Iu + nv * Iv) / lam
    ok = ((lam <= -min_curvature) & (-lam >= np.abs(half + root))
          & (np.abs(t * nu) <= _T_MAX) & (np.abs(t * nv) <= _T_MAX))
    ok[:, [0, -1]] = False                                        # outer rows: neighbours only
    k = np.argmax(np.where(ok, -lam, -np.inf), axis=1)            # strongest line pixel
    found = ok[np.arange(n), k]

    def at(a, kk):
        return np.take_along_axis(a, kk[:, None], axis=1)[:, 0]

    bu, bv, bt = at(nu, k), at(nv, k), at(t, k)
    gcol = bu[:, None] * Iu + bv[:, None] * Iv                    # n·∇I down the column
    dcol = bu[:, None] * Iuv + bv[:, None] * Ivv                  # its v-derivative
    y0, d0 = at(gcol, k), at(dcol, k)
    yn, dn = at(gcol, k + 1), at(dcol, k + 1)
    yp, dp = at(gcol, k - 1), at(dcol, k - 1)
    down = np.sign(y0) != np.sign(yn)
    up = ~down & (np.sign(yp) != np.sign(y0))
    s = np.where(down, _hermite_root(y0, d0, yn, dn), _hermite_root(yp, dp, y0, d0) - 1.0)
    refined = down | up
    u = np.where(refined, c, c + bt * bu)
    v = r + (k - M) + np.where(refined, s, bt * bv)
    raw, _ = _gather(img, r[None, :] + np.arange(-w, w + 1)[:, None], c)
    sat = raw[w - 2:w + 3].max(axis=0) >= _saturation(img, saturation) if n else found
    if sat.any():                                # clipped plateau: Hessian biased by aliasing
        x = np.arange(-w, w + 1)[:, None]
        gs = np.where(inside[:, sat], raw[:, sat] - det.bg[sat], 0)
        centre = _plateau_centre(gs, inside[:, sat], x, raw[:, sat] >= _saturation(img, saturation), det.noise)
        u[sat], v[sat], found[sat] = c[sat], r[sat] + centre, True
    keep = found & np.isfinite(u) & np.isfinite(v)
    return LineCentres(u[keep].astype(np.float64), v[keep].astype(np.float64),
                       det.gmax[keep].astype(np.float64), width[keep],
                       det.contrast[keep].astype(np.float64), sat[keep], det.ambiguous[keep])
