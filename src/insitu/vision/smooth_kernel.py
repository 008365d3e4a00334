"""The smoothing of the centres along the line (:func:`~insitu.vision.extract.smooth_centres`)
as one compiled pass: each point's quadratic over the window of its stretch."""

from __future__ import annotations

import numpy as np

from insitu.vision.detect_kernel import compiled, summed
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


@compiled
def jumps(u, v, jump_px):
    """Where v (n,) steps off the line between consecutive centres (n − 1,) bool (u (n,)
    sorted): by more than ``jump_px`` from what the line's slope in the frame (the median
    of dv/du over the steps of 0.5 < du < 1.5, which the steps themselves do not move; 0
    without one) gives over the columns between them. A line 40° across the image (a
    crossed pass) climbs 0.85 px a column: its v alone would jump at every wobble of speckle
    and leave pieces too short to keep, its last 7 columns on a top among them. The frame's
    slope, not a local one, which would follow a ghost's streak at another slope as readily
    as the line."""
    n = len(u)
    out = np.zeros(max(n - 1, 0), np.bool_)
    if n < 2:
        return out
    du, dv = u[1:] - u[:-1], v[1:] - v[:-1]
    near = (du > 0.5) & (du < 1.5)
    slope = np.median(dv[near] / du[near]) if near.any() else 0.0
    for i in range(n - 1):
        out[i] = abs(dv[i] - slope * du[i]) > jump_px
    return out


@compiled
def run_edges(u, v, jump_px):
    """(k + 1,) int64: the runs (:func:`~insitu.vision.extract.runs`) of u, v (n ≥ 1,) sorted by
    u: the runs cut where u skips a column (> 1.5) or v jumps (:func:`jumps`)."""
    cut = jumps(u, v, jump_px)
    edges = [0]
    for i in range(len(cut)):
        if u[i + 1] - u[i] > 1.5 or cut[i]:
            edges.append(i + 1)
    edges.append(len(u))
    return np.array(edges, np.int64)


@compiled
def kept_and_smoothed(col, v, peak, edges, h, jump_px, end_fraction, drop_short):
    """:func:`~insitu.vision.extract._smooth` of points sorted by u (col (n,) int64 their
    rounded u, v, peak (n,)) cut into runs at ``edges``: (n,) bool, the points kept (each
    run's first to last point with peak ≥ end_fraction × the run's median peak, in runs of
    at least ``drop_short`` such points), and the kept points' v smoothed (m,)
    (:func:`local_quadratic` over the stretches the kept points form: cut where the columns
    part by more than h + 1 or v jumps)."""
    n = len(v)
    keep = np.zeros(n, np.bool_)
    for s in range(len(edges) - 1):
        a, b = edges[s], edges[s + 1]
        level = end_fraction * np.median(peak[a:b]) if end_fraction > 0 else 0.0
        first, last = b, a - 1
        for i in range(a, b):
            if peak[i] >= level:
                first, last = min(first, i), i
        if last - first + 1 >= drop_short:
            keep[first:last + 1] = True
    kc, kv = col[keep], v[keep]
    m = len(kv)
    if m < 2:
        return keep, kv.copy()
    cut = jumps(kc.astype(np.float64), kv, jump_px)
    first, last = [0], []
    for i in range(m - 1):
        if kc[i + 1] - kc[i] > h + 1 or cut[i]:
            last.append(i)
            first.append(i + 1)
    last.append(m - 1)
    return keep, local_quadratic(kc, kv, np.array(first), np.array(last), h)
