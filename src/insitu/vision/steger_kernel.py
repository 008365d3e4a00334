"""Steger's per-column work (:func:`~insitu.vision.steger.steger`) as one compiled pass per
column: the Gaussian derivatives at the 2M + 1 rows about the detected peak, the Hessian's
normal, the strongest line pixel and its refinement to the column's crossing. The arithmetic
is numpy's in the same float32 steps, so the centres are those of the array form (the
derivatives' sums in another order: within float32 rounding)."""

from __future__ import annotations

import numpy as np

from insitu.vision.detect_kernel import compiled, median_of_3

_T_MAX = np.float32(0.6)   # |t·n| ≤ 0.5 px, plus room for the Taylor step's overshoot
_TINY = np.float32(1e-12)
_HALF, _TWO, _THREE = np.float32(0.5), np.float32(2.0), np.float32(3.0)


@compiled
def _hermite_root(y0, d0, y1, d1):
    """Root s in [0, 1] (float32) of the cubic Hermite interpolant of (y0, d0) at 0 and
    (y1, d1) at 1: Newton from the linear estimate, 4 steps."""
    one, zero = np.float32(1.0), np.float32(0.0)
    s = y0 / (y0 - y1 if y0 != y1 else one)
    s = zero if s < zero else (one if s > one else s)
    a2 = _THREE * (y1 - y0) - _TWO * d0 - d1
    a3 = _TWO * (y0 - y1) + d0 + d1
    for _ in range(4):
        p = y0 + s * (d0 + s * (a2 + s * a3))
        dp = d0 + s * (_TWO * a2 + s * (_THREE * a3))
        s = s - p / (dp if abs(dp) > _TINY else _TINY)
        s = zero if s < zero else (one if s > one else s)
    return s


@compiled
def _sign(x):
    return np.float32(1.0) if x > 0 else (np.float32(-1.0) if x < 0 else x)


_BLOCK = 64
"""Columns whose derivatives are worked out together (:func:`column_derivatives`): their
pixels, float32, fit the first-level cache."""


@compiled
def column_derivatives(img, r, c, h, M):
    """(5, 2M + 1, n) float32: Iu, Iv, Iuu, Ivv, Iuv at rows r − M … r + M of each column c
    (n,) of ``img`` (H, W) (borders clipped), by the kernels ``h`` (3, 2R + 1): along u,
    then v, each a sum over the kernel in its order. Columns go in blocks of :data:`_BLOCK`,
    each block's pixels laid out so that the sums run over its columns side by side."""
    H, W = img.shape
    K, n, k2 = h.shape[1], len(r), 2 * M + 1
    R, L = K // 2, k2 + K - 1
    X = np.empty((L, K, _BLOCK), np.float32)               # a block's pixels
    A = np.empty((3, L, _BLOCK), np.float32)               # smoothed, 1st, 2nd along u
    D = np.empty((5, k2, n), np.float32)
    for b0 in range(0, n, _BLOCK):
        nb = min(_BLOCK, n - b0)
        for i in range(nb):
            r0, c0 = r[b0 + i] - M - R, c[b0 + i] - R
            inside = r0 >= 0 and r0 + L <= H and c0 >= 0 and c0 + K <= W
            for li in range(L):
                row = r0 + li if inside else min(max(r0 + li, 0), H - 1)
                for q in range(K):
                    col = c0 + q if inside else min(max(c0 + q, 0), W - 1)
                    X[li, q, i] = np.float32(img[row, col])
        for li in range(L):
            a0, a1, a2 = A[0, li], A[1, li], A[2, li]
            a0[:nb], a1[:nb], a2[:nb] = 0, 0, 0
            for q in range(K):
                h0, h1, h2, x = h[0, q], h[1, q], h[2, q], X[li, q]
                for i in range(nb):
                    a0[i] += x[i] * h0
                    a1[i] += x[i] * h1
                    a2[i] += x[i] * h2
        for j in range(k2):
            iu, iv, iuu = D[0, j, b0:b0 + nb], D[1, j, b0:b0 + nb], D[2, j, b0:b0 + nb]
            ivv, iuv = D[3, j, b0:b0 + nb], D[4, j, b0:b0 + nb]
            iu[:], iv[:], iuu[:], ivv[:], iuv[:] = 0, 0, 0, 0, 0
            for q in range(K):
                h0, h1, h2 = h[0, q], h[1, q], h[2, q]
                s0, s1, s2 = A[0, j + q], A[1, j + q], A[2, j + q]
                for i in range(nb):
                    iu[i] += s1[i] * h0
                    iv[i] += s0[i] * h1
                    iuu[i] += s2[i] * h0
                    ivv[i] += s0[i] * h2
                    iuv[i] += s1[i] * h1
    return D


@compiled
def _eigen(D, j):
    """The Hessian's most negative eigenvalue and the other at row j of a column's
    derivatives D (5, 2M + 1) (Iu, Iv, Iuu, Ivv, Iuv), float32."""
    Iuu, Ivv, Iuv = D[2, j], D[3, j], D[4, j]
    half = (Iuu + Ivv) / _TWO
    d = (Iuu - Ivv) / _TWO
    root = np.sqrt(d * d + Iuv * Iuv)
    return half - root, half + root


@compiled
def _normal(D, j, lj):
    """The unit normal (n_u, n_v) of eigenvalue lj at row j of D (:func:`_eigen`) and the
    Taylor step t = −(n·∇I)/lj, float32."""
    Iu, Iv, Iuu, Ivv, Iuv = D[0, j], D[1, j], D[2, j], D[3, j], D[4, j]
    e1v, e2u = lj - Iuu, lj - Ivv
    if Iuv * Iuv + e1v * e1v >= e2u * e2u + Iuv * Iuv:
        a, b = Iuv, e1v
    else:
        a, b = e2u, Iuv
    norm = np.hypot(a, b)
    if norm < _TINY:
        a, b = np.float32(0.0), np.float32(1.0)
    else:
        a, b = a / norm, b / norm
    return a, b, -(a * Iu + b * Iv) / lj


@compiled
def steger_columns(img, r, c, h, M, min_curvature, across):
    """Steger's centres (u, v float64 (n,), found bool (n,)) of the columns ``c`` (n,) with
    their detected peaks at rows ``r`` (n,) of ``img`` (H, W): derivatives by the kernels
    ``h`` (3, 2R + 1) float32 (smoothing, first, second derivative) at rows r − M … r + M
    (borders clipped, :func:`column_derivatives`), the line pixel by the Hessian's test with
    ``min_curvature`` (float32), ``across``: a column without one measured down the column
    alone (steger's keywords). The normal is worked out only at rows whose eigenvalues can
    pass the test (and at the first row of a column with none, whose (u, v) is not found)."""
    n, k2 = len(r), 2 * M + 1
    u, v, found = np.empty(n), np.empty(n), np.zeros(n, np.bool_)
    derivatives = column_derivatives(img, r, c, h, M)      # Iu, Iv, Iuu, Ivv, Iuv
    for i in range(n):
        D = derivatives[:, :, i]
        best, k = -np.inf, 0
        bu, bv, bt = np.float32(0.0), np.float32(0.0), np.float32(0.0)
        for j in range(1, k2 - 1):                         # the Hessian's line pixel
            lj, other = _eigen(D, j)
            if lj <= -min_curvature and -lj >= abs(other) and -lj > best:
                a, b, tj = _normal(D, j, lj)
                if abs(tj * a) <= _T_MAX and abs(tj * b) <= _T_MAX:
                    best, k, bu, bv, bt = -lj, j, a, b, tj
        hit = best > -np.inf
        if not hit:
            bu, bv, bt = _normal(D, 0, _eigen(D, 0)[0])
        if across and not hit:                             # down the column alone
            best1, k1 = -np.inf, -1
            for j in range(1, k2 - 1):
                Iv, Ivv = D[1, j], D[3, j]
                t1 = -Iv / Ivv
                if Ivv <= -min_curvature and abs(t1) <= _T_MAX and -Ivv > best1:
                    best1, k1 = -Ivv, j
            if k1 >= 0:
                k, hit = k1, True
                bu, bv, bt = np.float32(0.0), np.float32(1.0), -D[1, k1] / D[3, k1]
        kn, kp = (k + 1) % k2, (k - 1) % k2
        y0 = bu * D[0, k] + bv * D[1, k]                   # n·∇I down the column
        d0 = bu * D[4, k] + bv * D[3, k]                   # its v-derivative
        yn, dn = bu * D[0, kn] + bv * D[1, kn], bu * D[4, kn] + bv * D[3, kn]
        yp, dp = bu * D[0, kp] + bv * D[1, kp], bu * D[4, kp] + bv * D[3, kp]
        down = _sign(y0) != _sign(yn)
        if down or _sign(yp) != _sign(y0):
            s = (_hermite_root(y0, d0, yn, dn) if down else _hermite_root(yp, dp, y0, d0))
            u[i] = c[i]
            v[i] = r[i] + (k - M) + (np.float64(s) - (0.0 if down else 1.0))
        else:
            u[i] = c[i] + np.float64(bt * bu)
            v[i] = r[i] + (k - M) + np.float64(bt * bv)
        found[i] = hit
    return u, v, found


@compiled
def moment_fit(m0, m1, m2, m3, m4, t0, t1, t2):
    """The quadratic fitted by moments: the normal equations [[m0, m1, m2], [m1, m2, m3],
    [m2, m3, m4]] · a = (t0, t1, t2) solved by cofactors; their determinant and a (constant,
    linear, quadratic; inf or NaN where the determinant is 0)."""
    c0, c1, c2 = m2 * m4 - m3 ** 2, m2 * m3 - m1 * m4, m1 * m3 - m2 ** 2
    c3, c4, c5 = m0 * m4 - m2 ** 2, m1 * m2 - m0 * m3, m0 * m2 - m1 ** 2
    det = m0 * c0 + m1 * c1 + m2 * c2
    return (det, (c0 * t0 + c1 * t1 + c2 * t2) / det, (c1 * t0 + c3 * t1 + c4 * t2) / det,
            (c2 * t0 + c4 * t1 + c5 * t2) / det)


@compiled
def _moment_vertex(m0, m1, m2, m3, m4, t0, t1, t2, half):
    """The vertex of the quadratic fitted by moments, NaN where its determinant is too small,
    it opens upwards or lies beyond ±half."""
    det, _, b, a = moment_fit(m0, m1, m2, m3, m4, t0, t1, t2)
    vertex = -b / (2 * a)
    if abs(det) > 1e-9 * max(m0, 1.0) ** 3 and a < 0 and abs(vertex) <= half:
        return vertex
    return np.nan


@compiled
def plateau_centres(raw, inside, sat, noise, unit):
    """:func:`_plateau` of each column of ``raw`` (k, n) float32 (the band of 2h + 1 rows
    centred on a clipped peak), ``inside`` and ``sat`` (k, n) bool: offsets (n,) px from
    the band's middle."""
    K, n = raw.shape
    out = np.empty(n)
    bg, g = np.empty(K), np.empty(K)
    run, near = np.empty(K, np.bool_), np.empty(K, np.bool_)
    for i in range(n):
        out[i] = _plateau(raw[:, i], inside[:, i], sat[:, i], noise, unit, bg, g, run, near)
    return out


@compiled
def clipped_centres(img, r, c, w, level, noise, unit):
    """:func:`plateau_centres` of the columns ``c`` (n,) of ``img`` (H, W) over the rows
    r − w … r + w about their peaks ``r`` (n,) (clipped to the frame; rows outside it not
    inside), the pixels at ``level`` (float32) or more clipped: offsets (n,) px from r."""
    H, K, n = img.shape[0], 2 * w + 1, len(r)
    out = np.empty(n)
    raw, inside, sat = np.empty(K, np.float32), np.empty(K, np.bool_), np.empty(K, np.bool_)
    bg, g = np.empty(K), np.empty(K)
    run, near = np.empty(K, np.bool_), np.empty(K, np.bool_)
    for i in range(n):
        for y in range(K):
            row = r[i] - w + y
            inside[y] = row >= 0 and row < H
            raw[y] = np.float32(img[min(max(row, 0), H - 1), c[i]])
            sat[y] = raw[y] >= level
        out[i] = _plateau(raw, inside, sat, noise, unit, bg, g, run, near)
    return out


@compiled
def _plateau(raw, inside, sat, noise, unit, bg, g, run, near):
    """The centre of one column's clipped plateau, offset px from the middle of ``raw`` (k,)
    float32 (k = 2h + 1, ``inside``, ``sat`` (k,) bool): the vertex of the log-parabola
    fitted by weighted moments to the unclipped rows of its flanks above the sloping
    background (a straight line between the medians of the 3 px at each end) by more than
    the floor (3 gray values of ``unit``, 3 ``noise``, the background's change across the
    band), joined to the middle while they fall away from it; else (fewer than 3 rows, none
    on a side, a vertex beyond ±h or opening upwards) :func:`_run_centroid`. bg, g (k,)
    float64 and run, near (k,) bool: work space."""
    K = len(raw)
    h = K // 2
    top = median_of_3(raw[0], raw[1], raw[2])                # the sloping background
    bot = median_of_3(raw[K - 3], raw[K - 2], raw[K - 1])
    mid, slope = (top + bot) / _TWO, (bot - top) / np.float32(2 * h)
    for y in range(K):
        bg[y] = np.float64(mid) + np.float64(slope) * (y - h)
        g[y] = np.float64(raw[y]) - bg[y] if inside[y] else 0.0
    floor = max(max(3.0 * unit, 3.0 * noise), abs(bg[K - 1] - bg[0]))
    vertex = np.nan
    if inside[h] and g[h] >= floor:        # the rows at the floor joined to the middle,
        lo, hi = h, h                      # falling away from it (or clipped)
        while lo > 0 and inside[lo - 1] and g[lo - 1] >= floor and (
                g[lo - 1] <= g[lo] or sat[lo - 1]):
            lo -= 1
        while hi < K - 1 and inside[hi + 1] and g[hi + 1] >= floor and (
                g[hi + 1] <= g[hi] or sat[hi + 1]):
            hi += 1
        m0 = m1 = m2 = m3 = m4 = t0 = t1 = t2 = 0.0         # the moments of the unclipped
        count = 0
        for y in range(lo, hi + 1):
            if not sat[y]:
                x, wgt = np.float64(y - h), g[y]
                wl = wgt * np.log(max(g[y], unit))
                p2 = x * x
                m0 += wgt
                m1 += x * wgt
                m2 += p2 * wgt
                m3 += p2 * x * wgt
                m4 += p2 * x * x * wgt
                t0 += wl
                t1 += x * wl
                t2 += p2 * wl
                count += 1
        below = lo < h and not sat[lo:h].all()
        beyond = hi > h and not sat[h + 1:hi + 1].all()
        if below and beyond and count >= 3:
            vertex = _moment_vertex(m0, m1, m2, m3, m4, t0, t1, t2, h)
    if not np.isfinite(vertex):
        vertex = _run_centroid(raw, inside, sat, bg, g, run, near)
    return vertex


@compiled
def _segment(mask, at, out):
    """``out`` (k,) bool: the run of True of ``mask`` (k,) holding ``at`` (none where
    mask[at] is False)."""
    out[:] = False
    if mask[at]:
        y = at
        while y >= 0 and mask[y]:
            out[y] = True
            y -= 1
        y = at + 1
        while y < len(mask) and mask[y]:
            out[y] = True
            y += 1


@compiled
def _run_centroid(raw, inside, sat, bg, g, run, near):
    """:func:`~insitu.vision.steger._run_centroid` of one column: raw, inside, sat (k,), its
    background bg and g = raw − bg (k,); run, near: (k,) bool work space."""
    K = len(raw)
    h = K // 2
    peak = h - 2
    for y in range(h - 1, h + 3):
        if raw[y] > raw[peak]:
            peak = y
    _segment(sat, peak, run)
    first, last = 0, K - 1
    if run.any():
        first, last = np.argmax(run), K - 1 - np.argmax(run[::-1])
    lo, hi = min(max(first - 3, 0), K - 1), min(max(last + 3, 0), K - 1)
    top = raw[peak]
    steep = abs(bg[K - 1] - bg[0]) > (top - max(bg[0], bg[K - 1])) / 2
    gmax = g.max()
    level = np.empty(K)
    for y in range(K):
        level[y] = (np.float64((top + max(raw[lo], raw[hi])) / _TWO) if steep
                    else bg[y] + gmax / 2)
        near[y] = (inside[y] and raw[y] > level[y]) or run[y]
    _segment(near.copy(), peak, near)
    total, moment = 0.0, 0.0
    for y in range(K):
        weight = np.float64(raw[y]) - level[y] if near[y] else 0.0
        moment += weight * (y - h)
        total += weight
    return moment / max(total, 1e-9)


@compiled
def widths_and_clipping(pre, img, r, c, w, half, level):
    """Each column's FWHM (float64 (n,), :func:`~insitu.vision.profile.fwhm`: the rows of
    ``pre`` (H, W) within ±w of the peak row r (n,) of column c (n,) standing above
    ``half`` (n,), joined to the peak's row) and whether ``img`` (H, W) reaches ``level``
    (float32) within ±2 rows of it (rows clipped to the frame), (n,) bool."""
    H = pre.shape[0]
    n = len(r)
    width, sat = np.empty(n), np.empty(n, np.bool_)
    for i in range(n):
        y, col, up, down = r[i], c[i], 0, 0
        for s in range(w + 1):
            if y - s < 0 or y - s >= H or not np.float32(pre[y - s, col]) > half[i]:
                break
            up += 1
        for s in range(w + 1):
            if y + s < 0 or y + s >= H or not np.float32(pre[y + s, col]) > half[i]:
                break
            down += 1
        width[i] = max(up + down - 1, 0)
        top = np.float32(img[min(max(y - 2, 0), H - 1), col])
        for s in range(-1, 3):
            top = max(top, np.float32(img[min(max(y + s, 0), H - 1), col]))
        sat[i] = top >= level
    return width, sat
