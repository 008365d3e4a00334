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
def steger_columns(img, r, c, h, M, min_curvature, across):
    """Steger's centres (u, v float64 (n,), found bool (n,)) of the columns ``c`` (n,) with
    their detected peaks at rows ``r`` (n,) of ``img`` (H, W): derivatives by the kernels
    ``h`` (3, 2R + 1) float32 (smoothing, first, second derivative) at rows r − M … r + M
    (borders clipped, :func:`column_derivatives`), the line pixel by the Hessian's test with
    ``min_curvature`` (float32), ``across``: a column without one measured down the column
    alone (steger's keywords)."""
    n, k2 = len(r), 2 * M + 1
    u, v, found = np.empty(n), np.empty(n), np.zeros(n, np.bool_)
    derivatives = column_derivatives(img, r, c, h, M)      # Iu, Iv, Iuu, Ivv, Iuv
    gcol, dcol = np.empty(k2, np.float32), np.empty(k2, np.float32)
    lam, nu, nv, t = (np.empty(k2, np.float32), np.empty(k2, np.float32),
                      np.empty(k2, np.float32), np.empty(k2, np.float32))
    for i in range(n):
        D = derivatives[:, :, i]
        best, k = -np.inf, 0
        for j in range(k2):                                # the Hessian's normal
            Iu, Iv, Iuu, Ivv, Iuv = D[0, j], D[1, j], D[2, j], D[3, j], D[4, j]
            half = (Iuu + Ivv) / _TWO
            d = (Iuu - Ivv) / _TWO
            root = np.sqrt(d * d + Iuv * Iuv)
            lj, other = half - root, half + root
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
            tj = -(a * Iu + b * Iv) / lj
            lam[j], nu[j], nv[j], t[j] = lj, a, b, tj
            ok = (lj <= -min_curvature and -lj >= abs(other) and abs(tj * a) <= _T_MAX
                  and abs(tj * b) <= _T_MAX and 0 < j < k2 - 1)
            if ok and -lj > best:
                best, k = -lj, j
        hit = best > -np.inf
        bu, bv, bt = nu[k], nv[k], t[k]
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
        for j in range(k2):
            gcol[j] = bu * D[0, j] + bv * D[1, j]          # n·∇I down the column
            dcol[j] = bu * D[4, j] + bv * D[3, j]          # its v-derivative
        kn, kp = (k + 1) % k2, (k - 1) % k2
        y0, d0, yn, dn, yp, dp = gcol[k], dcol[k], gcol[kn], dcol[kn], gcol[kp], dcol[kp]
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
    """:func:`~insitu.vision.steger._plateau_centre` of each column of ``raw`` (k, n) float32
    (the band of 2h + 1 rows centred on a clipped peak), ``inside`` and ``sat`` (k, n) bool:
    offsets (n,) px from the band's middle."""
    K, n = raw.shape
    h = K // 2
    out = np.empty(n)
    g, bg = np.empty(K), np.empty(K)
    above, use, run, near = (np.empty(K, np.bool_), np.empty(K, np.bool_),
                             np.empty(K, np.bool_), np.empty(K, np.bool_))
    m, t = np.empty(5), np.empty(3)                        # the moments' sums
    for i in range(n):
        top = median_of_3(raw[0, i], raw[1, i], raw[2, i])          # the sloping background
        bot = median_of_3(raw[K - 3, i], raw[K - 2, i], raw[K - 1, i])
        mid, slope = (top + bot) / _TWO, (bot - top) / np.float32(2 * h)
        for y in range(K):
            bg[y] = np.float64(mid) + np.float64(slope) * (y - h)
            g[y] = np.float64(raw[y, i]) - bg[y] if inside[y, i] else 0.0
        floor = max(max(3.0 * unit, 3.0 * noise), abs(bg[K - 1] - bg[0]))
        for y in range(K):                     # at the floor, falling away from the middle
            falls = (y == h or (y < h and g[y] <= g[y + 1]) or (y > h and g[y] <= g[y - 1]))
            above[y] = inside[y, i] and g[y] >= floor and (falls or sat[y, i])
            use[y] = inside[y, i] and g[y] >= floor and not sat[y, i]
        for step in (-1, 1):                   # only the run of rows joined to the middle
            joined = True
            for y in range(h, -1 if step < 0 else K, step):
                joined = joined and above[y]
                use[y] = use[y] and joined
        m[:], t[:] = 0.0, 0.0
        below = beyond = False
        count = 0
        for y in range(K):
            if use[y]:
                x, wgt = np.float64(y - h), g[y]
                ly = np.log(max(g[y], unit))
                p = 1.0
                for q in range(5):
                    m[q] += p * wgt
                    if q < 3:
                        t[q] += p * (wgt * ly)
                    p *= x
                below, beyond, count = below or y < h, beyond or y > h, count + 1
        vertex = np.nan
        if below and beyond and count >= 3:
            vertex = _moment_vertex(m[0], m[1], m[2], m[3], m[4], t[0], t[1], t[2], h)
        if not np.isfinite(vertex):
            vertex = _run_centroid(raw[:, i], inside[:, i], sat[:, i], bg, g, run, near)
        out[i] = vertex
    return out


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
