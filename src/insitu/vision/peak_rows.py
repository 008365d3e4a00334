"""Each column's candidate rows for the detection stage (:mod:`insitu.vision.detect`) of a
frame with an ``allow`` map or ridges: the frame laid out column by column, blanked outside
the band, where not allowed and off the ridges, and the row of each column's greatest and
second greatest candidate; and the band's rows, which every frame's search starts from."""

from __future__ import annotations

import cv2
import numpy as np

from insitu.vision.detect_kernel import compiled


def per_column(b, W: int) -> np.ndarray:
    """A band's end ``b`` (scalar or (W,)) as (W,) float64 (itself when it is one)."""
    a = np.asarray(b, np.float64)
    return a if a.shape == (W,) else np.broadcast_to(a, (W,))


def band_rows(shape, band):
    """The first and last row (W,) int64 of each column's band in a frame of ``shape``
    (H, W) (all rows without a band; −1 last where a column is not searched), the searched
    columns (W,) bool and the most rows a band has (:func:`band_limits`)."""
    H, W = shape
    if band is None:
        return np.zeros(W, np.int64), np.full(W, H - 1, np.int64), np.ones(W, bool), H
    blo, bhi = (np.ascontiguousarray(per_column(b, W)) for b in band)
    return band_limits(blo, bhi, H)


@compiled
def band_limits(blo, bhi, H):
    """:func:`band_rows` of the band's ends blo, bhi (W,) float64 (NaN: not searched) in a
    frame of H rows, in one pass: each column searched where ceil(blo) ≤ floor(bhi), both
    finite and within the frame's rows, its rows clipped to them."""
    W = len(blo)
    lo, hi, searched = np.zeros(W, np.int64), np.full(W, -1, np.int64), np.zeros(W, np.bool_)
    span = 0
    for x in range(W):
        flo, fhi = np.ceil(blo[x]), np.floor(bhi[x])
        if np.isfinite(flo) and np.isfinite(fhi) and flo <= fhi and flo <= H - 1 and fhi >= 0:
            searched[x] = True
            lo[x], hi[x] = int(min(max(flo, 0.0), H - 1.0)), int(min(max(fhi, 0.0), H - 1.0))
        span = max(span, hi[x] - lo[x])
    return lo, hi, searched, span + 1


@compiled
def band_extent(lo, hi, H):
    """The first and last of the columns whose band lo … hi (W,) float64 is finite, in order
    and meets the frame's H rows (−1, −1: none), the least lo and the greatest hi over them."""
    first, last, least, most = -1, -1, np.inf, -np.inf
    for x in range(len(lo)):
        a, b = lo[x], hi[x]
        if np.isfinite(a) and np.isfinite(b) and a <= b and b >= 0 and a <= H - 1:
            first = x if first < 0 else first
            last, least, most = x, min(least, a), max(most, b)
    return first, last, least, most


def search_rows(pre, band, allow, fill, ridge, thr):
    """The (W, H) array of each column's candidate values (a copy, ours to overwrite), for
    a frame with an ``allow`` map (H, W) bool or ridges (ridge > 0; a frame with neither is
    searched in its band by :mod:`insitu.vision.detect_kernel`): ``pre`` transposed,
    ``fill`` outside the column's band, where not allowed and (ridge > 0) where the column's
    white top-hat over 2·ridge + 1 rows stays below ``thr`` (or its (W, H) map); the first
    row of each column's band (W,), the most rows a band has and the searched columns (W,)
    bool."""
    lo, hi, searched, span = band_rows(pre.shape, band)
    search = cv2.transpose(pre)
    blocked = None if allow is None else ~cv2.transpose(allow.astype(np.uint8)).astype(bool)
    if ridge:
        hat = cv2.morphologyEx(search, cv2.MORPH_TOPHAT, np.ones((1, 2 * ridge + 1), np.uint8),
                               borderType=cv2.BORDER_REPLICATE)
        blocked = hat < thr if blocked is None else blocked | (hat < thr)
    if band is not None:
        dt = np.int16 if pre.shape[0] < 2**15 else np.int64      # the compares' speed
        rows = np.arange(pre.shape[0], dtype=dt)
        inside = (rows >= lo.astype(dt)[:, None]) & (rows <= hi.astype(dt)[:, None])
        blocked = ~inside if blocked is None else blocked | ~inside
    np.putmask(search, blocked, fill)
    return search, lo, span, searched


def peak_rows(search, lo, fill):
    """Each column's row of its greatest candidate (the first of equals), or the first row of
    its band where it has none (all ``fill``)."""
    j = np.argmax(search, axis=1)
    return np.where(search[np.arange(len(j)), j] == fill, lo, j)


def second_rows(search, j1, lo, fill, w, live, min_peak):
    """:func:`peak_rows` of ``search`` with each column's ±w rows about its first peak j1
    (W,) set to ``fill``, worked out only in the ``live`` columns (W,) bool (those whose first
    peak can pass) whose greatest value left reaches ``min_peak``; the first row of its band
    in every other column. Also (W,) bool: the columns worked out, the only ones whose
    second peak may pass (a band's first row can hold the first peak's flank)."""
    n = search.shape[1]
    out, cols = lo.copy(), np.flatnonzero(live)
    part = search[cols]
    guard = np.clip(j1[cols][:, None] + np.arange(-w, w + 1), 0, n - 1)
    part.reshape(-1)[guard + (np.arange(len(cols)) * n)[:, None]] = fill
    keep = part.max(axis=1, initial=fill) >= min_peak
    out[cols[keep]] = peak_rows(part[keep], lo[cols[keep]], fill)
    found = np.zeros(len(lo), bool)
    found[cols[keep]] = True
    return out, found
