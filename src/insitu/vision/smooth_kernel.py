"""The smoothing of the centres along the line (:func:`~insitu.vision.extract.smooth_centres`)
as one compiled pass: each point's quadratic over the window of its stretch."""

from __future__ import annotations

import numba
import numpy as np

from insitu.vision.detect_kernel import compiled

summed = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc"})
"""As ``compiled``, its sums taken in any order (vectorised): for a statistic whose last
bits do not matter (the wander's correlation length, rounded up to whole columns)."""
from insitu.vision.steger_kernel import moment_fit


@compiled
def local_quadratic(col, v, first, last, h):
    """v (n,) smoothed: each point's value of the quadratic (a straight line below 5 points
    or where the quadratic is degenerate; v itself below 2) fitted to the points of its
    stretch within ±h columns of its window's centre — the point's column, shifted to stay
    h columns inside the stretch (its middle when the stretch is shorter than the window).
    col (n,) int64 non-decreasing; stretches: points first[s] … last[s]."""
    out = np.empty(len(v))
    for s in range(len(first)):
        a, b = first[s], last[s]
        span = col[b] - col[a]
        lo = a                                     # the window's first point
        for i in range(a, b + 1):
            p = col[i] - col[a]
            centre = min(max(p, h), span - h) if span - h >= h else span // 2
            while col[lo] - col[a] < centre - h:
                lo += 1
            m0 = m1 = m2 = m3 = m4 = t0 = t1 = t2 = 0.0
            j = lo
            while j <= b and col[j] - col[a] <= centre + h:
                x = np.float64(col[j] - col[a] - centre)
                m0 += 1.0
                m1 += x
                m2 += x * x
                m3 += x * x * x
                m4 += x * x * x * x
                t0 += v[j]
                t1 += v[j] * x
                t2 += v[j] * (x * x)
                j += 1
            det, a0, a1, a2 = moment_fit(m0, m1, m2, m3, m4, t0, t1, t2)
            x = np.float64(p - centre)
            det2 = m0 * m2 - m1 ** 2
            if m0 >= 5 and abs(det) > 1e-9:
                out[i] = a0 + a1 * x + a2 * x * x
            elif m0 >= 2 and abs(det2) > 1e-9:
                b1 = (m0 * t1 - m1 * t0) / det2
                out[i] = (t0 - b1 * m1) / m0 + b1 * x
            else:
                out[i] = v[i]
    return out


@summed
def _detrended(v, coeffs, ends, out):
    """``out`` (n,): v (n,) less its Savitzky–Golay quadratic (the window's convolution
    ``coeffs`` (k,) inside, the hat matrix ``ends`` (k, k) of the first and last k points at
    the ends: scipy's savgol_filter, mode "interp"), less its mean."""
    n, k = len(v), len(coeffs)
    h = k // 2
    for i in range(h, n - h):
        s = 0.0
        for q in range(k):
            s += v[i - h + q] * coeffs[k - 1 - q]
        out[i] = v[i] - s
    for i in range(h):
        s, e = 0.0, 0.0
        for q in range(k):
            s += ends[i, q] * v[q]
            e += ends[k - h + i, q] * v[n - k + q]
        out[i], out[n - h + i] = v[i] - s, v[n - h + i] - e
    out -= out.mean()


@summed
def wander_scale(v, first, last, which, sizes, coeffs, ends, max_lag):
    """The integral scale 1 + 2 Σ ρ_k (up to ρ's first zero, k ≤ ``max_lag``) of the
    autocorrelation of the residuals of the runs v[first[i] … last[i] − 1] (v (n,) float64)
    about each run's quadratic trend over sizes[which[i]] points (``coeffs`` (m, K) and
    ``ends`` (m, K, K): :func:`~insitu.vision.extract._savgol_matrices` of each size,
    zero-padded to K), the products summed over the runs; 0 when their variance is 0."""
    acf = np.zeros(max_lag + 1)
    for i in range(len(first)):
        a, b, m = first[i], last[i], which[i]
        k = sizes[m]
        r = np.empty(b - a)
        _detrended(v[a:b], coeffs[m, :k], ends[m, :k, :k], r)
        for lag in range(max_lag + 1):
            s = 0.0
            for j in range(b - a - lag):
                s += r[j + lag] * r[j]
            acf[lag] += s
    if acf[0] <= 0:
        return 0.0
    rho = 0.0
    for lag in range(1, max_lag + 1):
        if acf[lag] / acf[0] <= 0:
            break
        rho += acf[lag] / acf[0]
    return 1.0 + 2.0 * rho
