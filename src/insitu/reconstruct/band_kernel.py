"""The band a commanded line can fall in (:func:`~insitu.reconstruct.plane.line_band`) as
compiled passes: the light plane's points at the two ends of the height range, and the two
projected edges interpolated over the image's columns (or rows), their envelope and which
way a higher surface moves the line. The arithmetic is numpy's, step for step (np.interp's
algorithm, np.fmin, np.fmax, the median's sign), so the band is the array form's."""

from __future__ import annotations

import numpy as np

from insitu.vision.detect_kernel import compiled


@compiled
def plane_points(start, end, plane, z, weights, axis):
    """(2k + 2, 3) float64: the k points (1 − s) · start + s · end (``weights`` (2, k): 1 − s
    and s) on the heights z[0], then z[1] (each point's coordinate ``axis`` (0: x, 1: y)
    solved from ``plane`` (4,) [A, B, C, D]), then start and end on z = 0."""
    k = weights.shape[1]
    p = np.zeros((2 * k + 2, 3))
    other = 1 - axis
    for e in range(2):
        for i in range(k):
            row = p[e * k + i]
            for d in range(2):
                row[d] = weights[0, i] * start[d] + weights[1, i] * end[d]
            row[2] = z[e]
            row[axis] = -(plane[other] * row[other] + plane[2] * z[e] + plane[3]) / plane[axis]
    p[2 * k, 0], p[2 * k, 1], p[2 * k + 1, 0], p[2 * k + 1, 1] = start[0], start[1], end[0], end[1]
    return p


@compiled
def _interp(xp, fp, n):
    """np.interp(0 … n − 1, xp, fp, left=NaN, right=NaN) of ``xp`` (k,) increasing, by
    numpy's steps: each position's last xp[j] ≤ x, the slope (fp[j + 1] − fp[j]) / (xp[j +
    1] − xp[j]) from there (from j + 1 where that gives NaN), fp[j] on an xp."""
    k = len(xp)
    out = np.full(n, np.nan)
    j = 0
    for i in range(int(min(max(np.ceil(xp[0]), 0.0), float(n))), n):
        x = np.float64(i)
        if x > xp[k - 1]:
            break
        while j + 1 < k and xp[j + 1] <= x:
            j += 1
        if j == k - 1 or xp[j] == x:
            out[i] = fp[j]
            continue
        slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
        y = slope * (x - xp[j]) + fp[j]
        if np.isnan(y):
            y = slope * (x - xp[j + 1]) + fp[j + 1]
            if np.isnan(y) and fp[j] == fp[j + 1]:
                y = fp[j]
        out[i] = y
    return out


@compiled
def band_edges(xa, ya, xb, yb, n, sign, margin):
    """The band over positions 0 … n − 1 along the line between two projected edges, each
    sorted along it (xa (ka,) increasing with ya (ka,) across; xb, yb): each edge
    interpolated (np.interp, NaN beyond its ends), the band lo = fmin − ``margin``, hi =
    fmax + ``margin`` (n,) float64, and the sign (int) of the median of the finite
    (edge b − edge a) · ``sign``: the side a higher surface puts the line (0: none finite)."""
    ea, eb = _interp(xa, ya, n), _interp(xb, yb, n)
    lo, hi = np.empty(n), np.empty(n)
    neg = pos = zero = 0
    top_neg, least_pos = -np.inf, np.inf
    for i in range(n):
        a, b = ea[i], eb[i]
        lo[i] = (b if np.isnan(a) else (a if np.isnan(b) else min(a, b))) - margin
        hi[i] = (b if np.isnan(a) else (a if np.isnan(b) else max(a, b))) + margin
    for i in range(n):
        rise = (eb[i] - ea[i]) * sign
        if not np.isfinite(rise):
            continue
        if rise < 0:
            neg, top_neg = neg + 1, max(top_neg, rise)
        elif rise > 0:
            pos, least_pos = pos + 1, min(least_pos, rise)
        else:
            zero += 1
    m = neg + zero + pos
    if m == 0:
        return lo, hi, 0
    if m % 2:                                # the middle one's sign
        mid = m // 2
        return lo, hi, -1 if mid < neg else (0 if mid < neg + zero else 1)
    first = -1 if m // 2 - 1 < neg else (0 if m // 2 - 1 < neg + zero else 1)
    second = -1 if m // 2 < neg else (0 if m // 2 < neg + zero else 1)
    if first != -1 or second != 1:           # the two middle ones' mean: their signs'
        return lo, hi, first if first == second else first + second
    mean = (top_neg + least_pos) / 2          # the greatest negative and the least positive
    return lo, hi, 1 if mean > 0 else (-1 if mean < 0 else 0)
