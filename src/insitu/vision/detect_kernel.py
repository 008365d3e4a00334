"""The detection stage's per-column work (:mod:`insitu.vision.detect`) as compiled passes down
each column of the filtered frame: each column's greatest and second greatest pixel in its
band (a frame without an ``allow`` map or ridges; the others: :mod:`insitu.vision.peak_rows`),
and the peak's plateau, background and contrast (every frame searched without ridges)."""

from __future__ import annotations

import cv2
import numba
import numpy as np

compiled = numba.njit(cache=True, nogil=True, error_model="numpy")
"""Compiled once per argument types, the machine code kept beside the module (__pycache__);
divisions by zero give inf or NaN, as numpy's."""
summed = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc"})
"""As ``compiled``, its sums taken in any order (vectorised): for a statistic whose last
bits do not matter (the wander's correlation length, rounded up to whole columns)."""


@compiled
def _greatest(line, lo, hi, fill):
    """The greatest of line[lo … hi], at least ``fill`` (a reduction the compiler vectorises
    for integer frames)."""
    best = fill
    for value in line[lo:max(hi + 1, lo)]:     # no index: nothing to wrap round
        best = max(best, value)
    return best


@compiled
def _holds(line, lo, n, value):
    """Whether line[lo … lo + n − 1] holds ``value`` (a vectorised count)."""
    count = 0
    for v in line[lo:lo + n]:
        count += v == value
    return count > 0


@compiled
def _first(line, lo, value):
    """The first index from ``lo`` where ``line`` holds ``value`` (there is one), 32 values
    at a time."""
    y = lo
    while y + 32 <= len(line) and not _holds(line, y, 32, value):
        y += 32
    while line[y] != value:
        y += 1
    return y


@compiled
def _peak(line, lo, hi, skip_lo, skip_hi, fill):
    """(row, value) of the first greatest of ``line``'s values lo … hi, those skip_lo …
    skip_hi left out; (lo, fill) where none exceeds ``fill``."""
    a, b = min(hi, skip_lo - 1), max(lo, skip_hi + 1)
    before, after = _greatest(line, lo, a, fill), _greatest(line, b, hi, fill)
    best = max(before, after)
    if best == fill:
        return lo, fill
    return (_first(line, lo, best) if before == best else _first(line, b, best)), best


def band_peaks(pre, lo, hi, searched, fill):
    """Each column's row of its greatest pixel in rows lo … hi (W,) of ``pre`` (H, W), the
    first of equals, lo where the band has none above ``fill``
    (:func:`~insitu.vision.peak_rows.peak_rows` of the band's search); and ``second(j1, w,
    live, min_peak)``: :func:`~insitu.vision.peak_rows.second_rows` of the same band, each
    ``live`` column's greatest pixel more than ``w`` rows from its first peak ``j1`` (W,)
    where that reaches ``min_peak``, lo elsewhere, and (W,) bool where it does. The rows all
    bands span are transposed once, so that each column's band lies in memory in a row."""
    top, bottom = (int(lo[searched].min()), int(hi[searched].max()) + 1) if searched.any() \
        else (0, 0)
    search = cv2.transpose(pre[top:bottom]) if bottom > top else np.zeros((len(lo), 0),
                                                                           pre.dtype)
    first, last, fill = lo - top, hi - top, pre.dtype.type(fill)

    def second(j1, w, live, min_peak):
        j2, found = _second_peaks(search, j1 - top, first, last, w, live, min_peak, fill)
        return j2 + top, found

    return _column_peaks(search, first, last, fill) + top, second


@compiled
def _column_peaks(search, lo, hi, fill):
    out = np.empty(len(lo), np.int64)
    for col in range(len(lo)):
        out[col] = _peak(search[col], lo[col], hi[col], hi[col] + 1, hi[col], fill)[0]
    return out


@compiled
def _second_peaks(search, j1, lo, hi, w, live, min_peak, fill):
    out, found = lo.copy(), np.zeros(len(lo), np.bool_)
    for col in range(len(lo)):
        if live[col]:
            at, best = _peak(search[col], lo[col], hi[col], j1[col] - w, j1[col] + w, fill)
            if best >= min_peak:
                out[col], found[col] = at, True
    return out, found


@compiled
def _px(pre, y, col):
    """pre[y, col] as float32, y clipped to the frame (the array form's gather)."""
    return np.float32(pre[min(max(y, 0), pre.shape[0] - 1), col])


@compiled
def median_of_3(a, b, c):
    """The median of three numbers."""
    return max(min(a, b), min(max(a, b), c))


@compiled
def column_stats(pre, j, w, searched, min_peak):
    """Each column's peak at row j (W,) of ``pre`` (H, W), worked out where the column is
    ``searched`` and its peak reaches ``min_peak``: row (the middle of the plateau of equal
    pixels from j down, up to w + 1 rows, or 4w + 1 for a clipped core), run (its length),
    gmax (the peak), bg (the mean of the medians of 3 px at each end of the band ±w rows
    about the row, widened by half of a plateau longer than 2 px), contrast (gmax minus the
    brighter end's: an edge of a bright region is no line), float32; elsewhere j, 1, 0, 0,
    0."""
    H, W = pre.shape
    row, run = j.copy(), np.ones(W, np.int64)
    gmax, bg, contrast = (np.zeros(W, np.float32), np.zeros(W, np.float32),
                          np.zeros(W, np.float32))
    for col in range(W):
        y = j[col]
        top_value = np.float32(pre[y, col])
        if not searched[col] or top_value < min_peak:
            continue
        n = 0                                      # the plateau from the first maximum
        for s in range(w + 1):
            if y + s >= H or np.float32(pre[y + s, col]) != top_value:
                break
            n += 1
        if n > w:                                  # a clipped core: its whole plateau
            n = 0
            for s in range(4 * w + 1):
                if y + s >= H or np.float32(pre[y + s, col]) != top_value:
                    break
                n += 1
        y = y + (n - 1) // 2
        reach = w + max(n - 2, 0) // 2
        up = median_of_3(_px(pre, y - reach, col), _px(pre, y - reach + 1, col),
                      _px(pre, y - reach + 2, col))
        dn = median_of_3(_px(pre, y + reach, col), _px(pre, y + reach - 1, col),
                      _px(pre, y + reach - 2, col))
        row[col], run[col], gmax[col] = y, n, top_value
        bg[col] = (up + dn) / np.float32(2.0)
        contrast[col] = top_value - max(up, dn)
    return row, run, gmax, bg, contrast


@compiled
def carry(img, ok, row, gmax, bg, min_peak, thr, searched, steps, upper, locked, run, shared):
    """:func:`~insitu.vision.chains.carry_ends` in place on ok, row (W,) and gmax, bg (W,)
    float64: the runs of at least ``run`` valid columns (cut where the row steps more than
    2 px off the frame's slope) carried on; the ends of one direction all from the columns
    as they were before that direction, as its array form."""
    H, W = img.shape
    cols = np.flatnonzero(ok)
    if len(cols) < 2:
        return
    dc, dr = np.diff(cols), np.diff(row[cols])
    slope = np.median(dr[dc == 1].astype(np.float64)) if (dc == 1).any() else 0.0
    gap = (dc > 1) | (np.abs(dr - slope) > 2)
    first = cols[np.concatenate((np.ones(1, np.bool_), gap))]
    last = cols[np.concatenate((gap, np.ones(1, np.bool_)))]
    line = last - first + 1 >= run
    for d, ends in ((-1, first[line]), (1, last[line])):
        ok0, row0, bg0 = ok.copy(), row.copy(), bg.copy()
        for e in ends:
            for k in range(1, steps + 1):
                c = e + d * k
                at = row0[e] + (slope * d) * k
                if c < 0 or c >= W or not searched[c]:
                    break
                if ok0[c] and not (k <= shared and upper * (row0[c] - at) < -2.0
                                   and not locked[c]):
                    break
                y0 = int(np.rint(at))
                v, y = -np.inf, 0
                for j in range(3):                 # the median along the row, best of 3 rows
                    yy = min(max(y0 - 1 + j, 0), H - 1)
                    med = median_of_3(np.float64(img[yy, max(c - 1, 0)]),
                                      np.float64(img[yy, c]),
                                      np.float64(img[yy, min(c + 1, W - 1)]))
                    if med > v:
                        v, y = med, yy
                if v < min_peak or v - bg0[e] < thr:
                    break
                ok[c], row[c], gmax[c], bg[c] = True, y, v, bg0[e]


@compiled
def _root(parent, a):
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@compiled
def chain_labels(V, OK, max_jump):
    """(2W,) int64: the chain each of the 2W candidates (V (2W,) rows, OK (2W,) bool; the
    first W a column's first peak, the next W its second) belongs to, as a representative
    candidate's index: valid candidates of columns 1 or 2 apart whose rows differ by at most
    max_jump px a column are linked (:func:`~insitu.vision.chains.continuity`)."""
    n = len(V)
    W = n // 2
    parent = np.arange(n)
    for d in (1, 2):
        for s in (0, W):
            for t in (0, W):
                for i in range(W - d):
                    a, b = s + i, t + i + d
                    if OK[a] and OK[b] and abs(V[a] - V[b]) <= max_jump * d:
                        ra, rb = _root(parent, a), _root(parent, b)
                        parent[max(ra, rb)] = min(ra, rb)
    for a in range(n):
        parent[a] = _root(parent, a)
    return parent


@compiled
def junction_columns(lab1, lab2, own1, own2, own_columns):
    """:func:`~insitu.vision.chains.junction` (W,) bool of the chain labels lab1, lab2 (W,)
    (in 0 … 2W − 1) and the columns own1, own2 (W,) bool each candidate has alone: each
    chain's first and last own column and their count, then each column's test."""
    W = len(lab1)
    lo, hi, n = np.full(2 * W, W), np.full(2 * W, -1), np.zeros(2 * W, np.int64)
    for lab, own in ((lab1, own1), (lab2, own2)):
        for col in range(W):
            if own[col]:
                k = lab[col]
                lo[k], hi[k], n[k] = min(lo[k], col), max(hi[k], col), n[k] + 1
    out = np.zeros(W, np.bool_)
    for col in range(W):
        a, b = lab1[col], lab2[col]
        if n[a] >= own_columns and n[b] >= own_columns:
            out[col] = (hi[a] < col and lo[b] > col) or (hi[b] < col and lo[a] > col)
    return out
