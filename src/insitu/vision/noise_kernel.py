"""The frame's noise estimate (:func:`~insitu.vision.profile.frame_noise`) of an integer frame
as one compiled pass: the 3 × 3 median of the sampled rows and their absolute differences,
counted in a histogram whose middle is the median. Integer values throughout: the same
number as the array form (medianBlur of the rows' strips, absdiff, calcHist)."""

from __future__ import annotations

import numpy as np

from insitu.vision.detect_kernel import compiled


@compiled
def _median_of_sorted(l0, l1, l2, m0, m1, m2, h0, h1, h2):
    """The median of the nine values of three sorted triples (l ≤ m ≤ h each): the median of
    the greatest least, the middle middle and the least greatest."""
    g = max(max(l0, l1), l2)
    a, b = min(m0, m1), max(m0, m1)
    m = max(a, min(b, m2))
    s = min(min(h0, h1), h2)
    a, b = min(g, m), max(g, m)
    return max(a, min(b, s))


@compiled
def _median_row(img, y, lo, mid, hi, out):
    """``out`` (W,): row y of the 3 × 3 median of ``img`` (H, W), the frame's edges
    replicated (medianBlur's border): each column's three rows sorted (lo, mid, hi (W,) work
    space), then the median of three columns' (a 3 × 3 median exactly). The inner columns
    read the sorted rows through shifted views, without index arithmetic: a loop the compiler
    vectorises, in the machine code the numba cache keeps as in a fresh compile."""
    H, W = img.shape
    ra, rb, rc = img[max(y - 1, 0)], img[y], img[min(y + 1, H - 1)]
    for x in range(W):
        p, q, r = ra[x], rb[x], rc[x]
        a, b = min(p, q), max(p, q)
        lo[x], mid[x], hi[x] = min(a, r), max(a, min(b, r)), max(b, r)
    n = max(W - 2, 0)
    l0, l1, l2, m0, m1, m2 = lo[:n], lo[1:n + 1], lo[2:n + 2], mid[:n], mid[1:n + 1], mid[2:n + 2]
    h0, h1, h2, o = hi[:n], hi[1:n + 1], hi[2:n + 2], out[1:n + 1]
    for x in range(n):
        o[x] = _median_of_sorted(l0[x], l1[x], l2[x], m0[x], m1[x], m2[x], h0[x], h1[x], h2[x])
    for x, p, q in ((0, 0, min(1, W - 1)), (W - 1, max(W - 2, 0), W - 1)):
        out[x] = _median_of_sorted(lo[p], lo[x], lo[q], mid[p], mid[x], mid[q], hi[p], hi[x],
                                   hi[q])


@compiled
def median_row_differences(img, rows_a, rows_b):
    """The middle (float, the mean of the two middle order statistics) of |m(a, x) − m(b, x)|
    over the row pairs (rows_a[i], rows_b[i]) and every second column x, m the 3 × 3 median
    of the integer frame ``img`` (H, W) (any layout: a transposed view too)."""
    H, W = img.shape
    lo, mid, hi = (np.empty(W, img.dtype), np.empty(W, img.dtype), np.empty(W, img.dtype))
    ma, mb = np.empty(W, img.dtype), np.empty(W, img.dtype)
    top = 256                                      # the differences' bound: 8 bits
    if img.itemsize > 1:                           # or the sampled rows' greatest value
        top = 0
        for rows in (rows_a, rows_b):
            for y in rows:
                for yy in range(max(y - 1, 0), min(y + 2, H)):
                    top = max(top, int(img[yy].max()) + 1)
    counts = np.zeros((4, top), np.int64)          # four tallies: no chain of increments
    for i in range(len(rows_a)):
        _median_row(img, rows_a[i], lo, mid, hi, ma)
        _median_row(img, rows_b[i], lo, mid, hi, mb)
        for x in range(W):
            ma[x] = max(ma[x], mb[x]) - min(ma[x], mb[x])
        for x in range(0, W, 2):
            counts[(x >> 1) & 3, ma[x]] += 1
    counts = counts.sum(axis=0)
    m = len(rows_a) * ((W + 1) // 2)
    k1, k2 = (m - 1) // 2, m // 2                  # the two middle order statistics
    total, s1, s2 = 0, -1, -1
    for value in range(len(counts)):
        total += counts[value]
        if s1 < 0 and total > k1:
            s1 = value
        if total > k2:
            s2 = value
            break
    return (s1 + s2) / 2.0


@compiled
def _read(img, k, axis, lo, hi, step):
    """Whether row k (``axis`` 0; its columns lo ≤ c ≤ hi) or column k (axis 1; its rows lo,
    lo + step, … ≤ hi: a column's pixels lie far apart) of ``img`` holds a value other than 0."""
    if axis == 0:
        for c in range(lo, hi + 1):
            if img[k, c] != 0:
                return True
        return False
    for r in range(lo, hi + 1, step):
        if img[r, k] != 0:
            return True
    return False


@compiled
def _edge(img, out, inside, axis, lo, hi, step):
    """The first row or column read (:func:`_read`) from ``out`` (not read) towards
    ``inside`` (read), by bisection."""
    while abs(inside - out) > 1:
        mid = (out + inside) // 2
        if _read(img, mid, axis, lo, hi, step):
            inside = mid
        else:
            out = mid
    return inside


@compiled
def read_bounds(img, step):
    """(r0, r1, c0, c1): the rectangle of the integer frame ``img`` (H, W) holding its values
    other than 0 — the grid's (every ``step`` px) points other than 0 bounded, the edges
    bisected to the pixel; (0, H, 0, W) when every grid point, or none, holds one."""
    H, W = img.shape
    i0, i1, j0, j1, zeros = H, -1, W, -1, 0
    for i in range(0, H, step):
        for j in range(0, W, step):
            if img[i, j] == 0:
                zeros += 1
            else:
                i0, i1, j0, j1 = min(i0, i), max(i1, i), min(j0, j), max(j1, j)
    if zeros == 0 or i1 < 0:
        return 0, H, 0, W
    r0 = _edge(img, i0 - step if i0 else -1, i0, 0, j0, j1, step)
    r1 = _edge(img, min(i1 + step, H), i1, 0, j0, j1, step) + 1
    c0 = _edge(img, j0 - step if j0 else -1, j0, 1, i0, i1, step)
    c1 = _edge(img, min(j1 + step, W), j1, 1, i0, i1, step) + 1
    return r0, r1, c0, c1
