"""Tracks of ridge candidates across scan lines, for anyone's photographs (the ``ridge`` mode of
:mod:`insitu.vision.detect`): a laser stripe is one thin ridge running on across the frame,
clutter (the edge of a laser-coloured chair, a lit window's frame) a short one. Where the
stripe dims (a dark mark of a board) a piece of clutter can be the brightest ridge of the scan
line; the stripe is then still one of its few brightest ridges, and the one on the longest
track.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

CANDIDATES = 5
"""Ridges per scan line followed: the brightest, then the brightest more than a window away
from those, and so on (on a full-HD board's dark dots the stripe was among the 5 brightest
in 95 % of the scan lines, the brightest in 62 %)."""
BRIDGE, BRIDGE_SHARE = 80, 0.125
"""Most scan lines a track is carried across (:func:`track_length`): 80, or an eighth of
the scan lines of a larger frame (a stripe lost along the edge of a dark square)."""
LINK = 2
"""Scan lines apart that two candidates may be linked across (a missing line or one)."""
RIVAL, PIECE = 1.0, 0.25
"""Least span of the tracks running mostly beside the longest one on one side of it, as a
share of its length, from which they rival it (:class:`AmbiguousStripe`): a stripe lost on a
board's dark squares or broken in two, beside its reflection in a glossy floor, spans as many
scan lines as the reflection holds. Only tracks of at least PIECE of its length count. On
benchmarks/clipped_white.py's tune and spent seeds the rivals of a stripe measured right span
less than 0.9–1.0 of it, those of a reflection taken for the stripe 1.1–1.4 of it."""


class AmbiguousStripe(ValueError):
    """Tracks beside the longest that span as many scan lines as it holds (:data:`RIVAL`):
    which is the stripe cannot be told. ``rows``: ((lo, hi), (lo, hi)) the longest's and its rival's
    cross coordinates (px); ``scan``: (first, last) the scan lines both hold a candidate in."""

    def __init__(self, rows, scan):
        super().__init__(f"two tracks at rows {rows[0]} and {rows[1]} in columns {scan}")
        self.rows, self.scan = rows, scan


def candidates(search: np.ndarray, fill, w: int, stats, k: int = CANDIDATES):
    """The ``k`` brightest ridges of each column of ``search`` (W, span) (``fill`` where no
    pixel may be taken): its pixels that are the brightest within ±``w`` rows of their column
    (the first of a plateau's). ``stats(j, cols)`` (j, cols (n,) int: each candidate's row in
    its column's span, and its column) → a tuple of (n,) arrays whose 5th is its validity.
    Returns one (k, W) array per field of ``stats``, the columns' candidates brightest first
    (not valid where a column has fewer)."""
    W, span = search.shape
    top = cv2.dilate(search, np.ones((1, 2 * w + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
    peak = cv2.bitwise_and(cv2.compare(search, top, cv2.CMP_EQ),
                           cv2.compare(search, fill, cv2.CMP_NE))
    at = cv2.findNonZero(peak)
    at = np.zeros((0, 2), np.int64) if at is None else at.reshape(-1, 2).astype(np.int64)
    j, cols = at[:, 0], at[:, 1]                       # row-major: by column, then row
    first = np.ones(len(cols), bool)
    first[1:] = (cols[1:] != cols[:-1]) | (j[1:] != j[:-1] + 1)
    cols, j = cols[first], j[first]                    # a plateau's first pixel
    order = np.lexsort((-search[cols, j].astype(np.float64), cols))
    cols, j = cols[order], j[order]
    rank = np.arange(len(cols)) - np.searchsorted(cols, cols)
    cols, j, rank = cols[rank < k], j[rank < k], rank[rank < k]
    fields = list(stats(j, cols))
    out = []
    for f in fields:
        a = np.zeros((k, W), f.dtype)
        a[rank, cols] = f
        out.append(a)
    return out


def _components(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """(n,) label of each of n nodes: the connected components of the links src–dst."""
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _bridged(label, col, row, bridge: int, max_jump: float) -> np.ndarray:
    """(n,) label of each node's track once pieces that go on across a gap are joined: piece
    B starting at most ``bridge`` columns after piece A ends, where each one's straight line
    (least squares over its nodes) carried across the gap meets the other's end row within
    ``max_jump`` plus a tenth of the gap (the stripe lost on a dark mark of the board).
    label, col, row: (n,) the valid nodes' piece, column and row; pieces of fewer than 3
    nodes are left alone."""
    m = int(label.max(initial=-1)) + 1
    cnt = np.bincount(label, minlength=m).astype(np.float64)
    sc, sr = (np.bincount(label, a, m) for a in (col, row))
    scc, scr = np.bincount(label, col * col, m), np.bincount(label, col * row, m)
    den = cnt * scc - sc * sc
    slope = np.divide(cnt * scr - sc * sr, den, out=np.zeros(m), where=den > 0)
    first, last = np.full(m, np.iinfo(np.int64).max), np.full(m, -1)
    np.minimum.at(first, label, col)
    np.maximum.at(last, label, col)

    def end_row(end):
        at = col == end[label]
        return np.bincount(label[at], row[at], m) / np.maximum(np.bincount(label[at],
                                                                           minlength=m), 1)
    mean_c, mean_r = sc / np.maximum(cnt, 1), sr / np.maximum(cnt, 1)
    big = np.flatnonzero(cnt >= 3)
    a, b = big[:, None], big[None, :]
    gap = first[b] - last[a]
    tol = max_jump + 0.1 * gap
    sab = np.where(cnt[a] >= cnt[b], slope[a], slope[b])       # the longer piece's slope
    join = np.zeros(gap.shape, bool)
    for r0, r1 in ((end_row(first), end_row(last)),
                   (mean_r + slope * (first - mean_c), mean_r + slope * (last - mean_c))):
        join |= (gap > 0) & (gap <= bridge) & (np.abs(r1[a] + sab * gap - r0[b]) <= tol)
    ia, ib = np.nonzero(join)
    return _components(m, big[ia], big[ib])[label]


def _tracks(row: np.ndarray, ok: np.ndarray, max_jump: float, bridge: int | None):
    """(k, W) int: the scan lines (columns) of the track each candidate lies on, 0 where it is
    not valid, and (k, W) each candidate's track (−1: not valid). row, ok: (k, W) the candidates'
    rows (px) and validity. A track links valid candidates of columns up to :data:`LINK` apart whose
    rows differ by at most ``max_jump`` px per column, and goes on across gaps of up to ``bridge``
    columns (:func:`_bridged`)."""
    k, W = row.shape
    bridge = max(BRIDGE, round(BRIDGE_SHARE * W)) if bridge is None else bridge
    node = np.arange(k * W).reshape(k, W)
    src, dst = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for d in range(1, min(LINK, W - 1) + 1):                  # (k, k, W − d) at once
        m = (ok[:, None, :-d] & ok[None, :, d:]
             & (np.abs(row[:, None, :-d] - row[None, :, d:]) <= max_jump * d))
        a, b, c = np.nonzero(m)
        src.append(node[a, c])
        dst.append(node[b, c + d])
    label = _components(k * W, np.concatenate(src), np.concatenate(dst)).reshape(k, W)
    col = np.broadcast_to(np.arange(W), (k, W))[ok]
    track = np.full((k, W), -1)
    track[ok] = _bridged(np.unique(label[ok], return_inverse=True)[1], col,
                         row[ok].astype(np.float64), bridge, max_jump)
    pairs = np.unique(track[ok] * W + col)
    length = np.bincount(pairs // W, minlength=k * W)
    return np.where(ok, length[np.maximum(track, 0)], 0), track


def track_length(row: np.ndarray, ok: np.ndarray, max_jump: float,
                 bridge: int | None = None) -> np.ndarray:
    """(k, W) int: the scan lines of the track each candidate lies on (:func:`_tracks`)."""
    return _tracks(row, ok, max_jump, bridge)[0]


def on_longest_track(fields, max_jump: float, alone: bool = False):
    """Per column, the valid candidate on the longest track (:func:`track_length`; of two on
    equally long tracks the one of higher contrast): ``fields`` (row, gmax, bg, contrast,
    ok, run), each (k, W), as :func:`candidates` gives them. Returns the same six (W,)
    and ambiguous (W,) bool: the column had more than one valid candidate. A column the
    longest track (the stripe) has no candidate in gets none from a track that runs mostly
    beside the stripe (more than half its candidates in columns the stripe has one in),
    between the stripe's ends or past them: that is something else (a reflection of it in a
    glossy floor, the edge of a square it runs along). A track only in the stripe's gaps or
    past its ends (the stripe on a step's top, on a wall beside the board) stays.
    alone: AmbiguousStripe where tracks beside it rival it (:func:`_no_rival`)."""
    row, ok, contrast = fields[0], fields[4], fields[3]
    length, track = _tracks(row, ok, max_jump, None)
    score = np.where(ok, length + contrast / (1.0 + np.abs(contrast).max(initial=0.0)), -1.0)
    pick = np.argmax(score, axis=0)[None, :]
    chosen = [np.take_along_axis(f, pick, axis=0)[0] for f in fields]
    chosen[4] = ok.any(axis=0)
    if ok.any():
        longest = track.ravel()[np.argmax(length)]
        stripe = (track == longest).any(axis=0)
        m = int(track.max()) + 1
        beside = (np.bincount(track[ok], stripe[np.nonzero(ok)[1]], minlength=m)
                  > 0.5 * np.bincount(track[ok], minlength=m))
        if alone:
            _no_rival(track, length, row, beside, longest)
        chosen[4] &= stripe | ~beside[np.take_along_axis(track, pick, axis=0)[0]]
    return (*chosen, ok.sum(axis=0) > 1)


def _no_rival(track, length, row, beside, longest) -> None:
    """AmbiguousStripe if the tracks lying ``beside`` the ``longest`` (m,) bool on one side of
    it, each at least :data:`PIECE` of its length, span (first to last scan line) at least
    :data:`RIVAL` of its length: pieces of one line as long as it once its gaps are bridged.
    track, length, row: (k, W) as :func:`_tracks` and :func:`candidates` give them."""
    ok = track >= 0
    size = np.zeros(len(beside), np.int64)
    size[track[ok]] = length[ok]
    on = track == longest
    at = on.any(axis=0)
    mid = np.where(on, row, 0).sum(axis=0) / np.maximum(on.sum(axis=0), 1)    # (W,)
    keep = beside & (size >= PIECE * size[longest])
    keep[longest] = False
    k, c = np.nonzero(ok & keep[np.maximum(track, 0)] & at[None, :])
    side = np.sign(np.bincount(track[k, c], row[k, c] - mid[c], minlength=len(keep)))
    col = np.broadcast_to(np.arange(track.shape[1]), track.shape)
    for s in (-1, 1):
        group = ok & (keep & (side == s))[np.maximum(track, 0)]
        if not group.any():
            continue
        first, last = int(col[group].min()), int(col[group].max())
        if last - first + 1 >= RIVAL * size[longest]:
            span = np.flatnonzero(at)
            rows = tuple((int(row[a].min()), int(row[a].max())) for a in (on, group))
            raise AmbiguousStripe(rows, (max(first, int(span[0])), min(last, int(span[-1]))))
