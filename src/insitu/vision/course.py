"""A photograph's stripe kept on its course: the centres on no laser-coloured ridge dropped
(:func:`on_laser`: a bright square's edge beside the stripe), the stretches of centres that
slid off it onto the rim of a dark mark or a bright square's edge dropped (:func:`on_course`)
or, where the laser colour's excess runs on beside them, replaced by its centres
(:func:`off_the_excess`; the gaps filled from the excess by :mod:`insitu.vision.excess_fill`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from insitu.vision.detect import LineCentres

FLANKS = 0.5
"""Least laser colour on each side of a centre that is not white, of the most within reach
(:func:`on_laser`)."""
FIELDS = ("u", "v", "peak", "width", "contrast", "saturated", "ambiguous")
"""A :class:`LineCentres`' per-centre arrays."""
FILL_PX = 4.0
"""How far (px) a centre filling a gap may lie from the course of the stripe's centres on
either side (:func:`~insitu.vision.excess_fill.fill_gaps`)."""


def kept(c: LineCentres, keep: np.ndarray | slice) -> LineCentres:
    """``c``'s centres at ``keep`` ((N,) bool, indices or a slice)."""
    return replace(c, **{f: getattr(c, f)[keep] for f in FIELDS})


def in_frame(c: LineCentres, shape: tuple[int, int]) -> LineCentres:
    """``c`` without the centres outside the frame (H, W) ``shape``: a flank fit of a
    plateau with no curvature puts its vertex anywhere, and one such centre spoils the
    course its neighbours are judged by (:func:`on_course`)."""
    H, W = shape
    keep = (c.u >= 0) & (c.u <= W - 1) & (c.v >= 0) & (c.v <= H - 1)
    if keep.all():
        return c
    return kept(c, keep)


def on_laser(c: LineCentres, bgr: np.ndarray, channel: int, white: float, along_rows: bool,
             reach: int) -> LineCentres:
    """``c`` without the centres that lie on no laser-coloured ridge: a centre stays where its
    pixel is white (all three channels ≥ ``white``: a clipped core), or where the laser's
    excess X = I_c − (I_a + I_b) / 2 reaches :data:`FLANKS` of its greatest value within
    ±``reach`` px across the line on both sides — from the centre up to ``reach`` px before it
    and from it up to ``reach`` px after it. A stripe is a ridge of the laser's colour: both
    its flanks carry it, also round a core clipped white. A bright square's edge beside the
    stripe is a neutral step: the methods' centre pulled onto it has the stripe's colour on
    one side only. bgr: (H, W, 3) the photograph; channel: the laser's (BGR index)."""
    if not len(c):
        return c
    H, W = bgr.shape[:2]
    s = np.round(c.u if along_rows else c.v).astype(np.int64)
    x = np.round(c.v if along_rows else c.u).astype(np.int64)
    across = np.clip(x[None, :] + np.arange(-reach, reach + 1)[:, None], 0,
                     (H if along_rows else W) - 1)
    px = bgr[across, s] if along_rows else bgr[s, across]              # (2 reach + 1, n, 3)
    px = px.astype(np.float32)
    others = [k for k in range(3) if k != channel]
    ex = px[..., channel] - (px[..., others[0]] + px[..., others[1]]) / 2
    flanks = np.minimum(ex[:reach + 1].max(axis=0), ex[reach:].max(axis=0))
    keep = (px[reach].min(axis=1) >= white) | (flanks >= FLANKS * ex.max(axis=0))
    if keep.all():
        return c
    return kept(c, keep)


def on_course(c: LineCentres, along_rows: bool, half: float) -> LineCentres:
    """``c`` without the centres off the stripe's course by more than :data:`FILL_PX`: the
    running median of all centres over ±``half`` scan lines (a median keeps a step in depth),
    their median slope taken out first; a piece shorter than ``half`` (pieces part where the
    stripe, its slope taken out, jumps more than FILL_PX plus a tenth of the scan lines
    between) is judged by its neighbours instead (:func:`_between_neighbours`), or by those
    on one side alone at a step. A stripe is straight over that span; a stretch of centres
    slid onto the rim of a dark mark or onto a bright square's edge beside it is off it."""
    s = np.round(c.u if along_rows else c.v).astype(np.int64)
    x = c.v if along_rows else c.u
    if len(s) < 3:
        return c
    order = np.argsort(s, kind="stable")
    s, x = s[order], x[order]
    h = max(int(half), 1)
    slope, cut = _pieces(s, x, h)
    flat = x - slope * s
    mid = _running_median(s, flat, h)
    first = np.r_[0, np.flatnonzero(np.diff(cut)) + 1]
    short = (s[np.r_[first[1:], len(s)] - 1] - s[first] < h)[cut]
    on = _between_neighbours(s, x, cut, h, np.abs(flat - mid) <= FILL_PX, short)
    keep = np.zeros(len(s), bool)
    keep[order] = on
    if keep.all():
        return c
    return kept(c, keep)


def _pieces(s: np.ndarray, x: np.ndarray, h: int) -> tuple[float, np.ndarray]:
    """The centres' median slope and (n,) piece labels: pieces part where the centres (s, x:
    (n,) scan line and cross coordinate, sorted by s), that slope taken out, jump more than
    :data:`FILL_PX` plus a tenth of the scan lines between, or more than ``h`` scan lines
    lie between."""
    ds, dx = np.diff(s), np.diff(x)
    slope = float(np.median(dx[ds == 1])) if (ds == 1).any() else 0.0
    return slope, np.r_[0, np.cumsum((np.abs(dx - slope * ds) > FILL_PX + 0.1 * ds) | (ds > h))]


def _running_median(s: np.ndarray, flat: np.ndarray, h: int) -> np.ndarray:
    """(n,) the median of ``flat`` (n,) over the centres within ±``h`` scan lines of each
    (``s`` (n,) sorted), from ≤ 33 samples of each window."""
    dense = np.full(int(s[-1] - s[0]) + 1 + 2 * h, np.inf)
    dense[s - s[0] + h] = flat
    step = max(1, h // 16)
    win = np.sort(np.lib.stride_tricks.sliding_window_view(dense, 2 * h + 1)[s - s[0], ::step],
                  axis=1)
    n = np.isfinite(win).sum(axis=1)
    return (np.take_along_axis(win, ((n - 1) // 2)[:, None], 1)[:, 0]
            + np.take_along_axis(win, (n // 2)[:, None], 1)[:, 0]) / 2


def off_the_excess(c: LineCentres, along_rows: bool, half: float, run: int,
                   fill) -> LineCentres:
    """``fill(c)`` (``c`` with its gaps filled from the laser's excess,
    :func:`~insitu.vision.excess_fill.filled`),
    with the excess's centres in place of the centres beside them: ``run`` or more centres
    in a row (a stripe's least length in scan lines) that lie more than :data:`FILL_PX` / 2
    off the stripe's course (the running median over ±2 × ``half`` scan lines, its median
    slope taken out: longer than a board's square) are taken out, and where the excess's
    centres then fill their scan lines more than FILL_PX from them, ``run`` or more in a
    row, the laser's colour runs on along the course and the centres lie beside it on
    something else (a bright square's edge lit by the halo, brighter than the stripe on the
    dark square next to it: clipped_white spent seed 6005). A stripe on a raised surface is
    the laser's colour there: it stays; so does a centre beside one scan line's excess peak
    (a glint, a mark's rim)."""
    s = np.round(c.u if along_rows else c.v).astype(np.int64)
    x = c.v if along_rows else c.u
    if len(s) < 3:
        return fill(c)
    order = np.argsort(s, kind="stable")
    slope = _pieces(s[order], x[order], 1)[0]
    off = np.zeros(len(s), bool)
    off[order] = _runs(np.abs(x[order] - slope * s[order] - _running_median(
        s[order], x[order] - slope * s[order], 2 * max(int(half), 1))) > FILL_PX / 2, run)
    out = fill(c)
    if not off.any():
        return out
    f = fill(kept(c, ~off))
    fs = np.round(f.u if along_rows else f.v).astype(np.int64)
    at = np.searchsorted(fs, s).clip(0, max(len(fs) - 1, 0))
    beside = off & (fs[at] == s) & (np.abs((f.v if along_rows else f.u)[at] - x) > FILL_PX)
    beside[order] = _runs(beside[order], run)
    if not beside.any():
        return out
    o = np.round(out.u if along_rows else out.v).astype(np.int64)
    on, at = np.isin(o, s[beside]), np.searchsorted(fs, o).clip(0, len(fs) - 1)
    return replace(out, **{k: np.where(on, getattr(f, k)[at], getattr(out, k))
                           for k in FIELDS})


def _runs(a: np.ndarray, run: int) -> np.ndarray:
    """(n,) bool: ``a`` (n,) bool where it is True at least ``run`` times in a row."""
    edge = np.diff(np.r_[0, a.astype(np.int8), 0])
    start, end = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
    long = end - start >= run
    mark = np.zeros(len(a) + 1, np.int64)
    np.add.at(mark, start[long], 1)
    np.add.at(mark, end[long], -1)
    return np.cumsum(mark)[:-1] > 0


def _between_neighbours(s, x, cut, h, median, short) -> np.ndarray:
    """(n,) bool: ``median`` (the running median's verdict) on the long pieces (labels
    ``cut``, (n,); ``short``: (n,) bool, the centres on pieces of fewer than ``h`` scan
    lines); False on the short pieces that lie more than :data:`FILL_PX` off the straight
    line fitted through the other pieces' centres within ``h`` scan lines before and after
    them, where those lie on it (median residual ≤ FILL_PX / 4) on both sides, unless they
    continue the centres kept on one side alone across a step (:func:`_one_side`). Repeated
    without the pieces found off until no more is: a piece off the course is no neighbour to
    judge another by (stretches slid onto the rims of the same dark mark, one beside the
    other); a piece left with fewer than 3 neighbours on a side that way gets ``median``'s
    verdict. s, x: (n,) scan line and cross coordinate, sorted by s."""
    keep = median | short
    alive = np.ones(len(s), bool)                   # not on a short piece found off
    first = np.r_[0, np.flatnonzero(np.diff(cut)) + 1]
    last = np.r_[first[1:], len(s)] - 1
    pieces = [(a, b) for a, b in zip(first, last) if short[a]]
    dropped = True
    while dropped:
        dropped, left = False, []
        for a, b in pieces:
            side, both = _sides(s, cut, a, b, h, alive)
            if not both:
                if not alive.all() and _sides(s, cut, a, b, h, np.ones(len(s), bool))[1]:
                    keep[a:b + 1] = median[a:b + 1]
                continue
            fit = np.polyfit(s[side], x[side], 1)
            if (np.median(np.abs(np.polyval(fit, s[side]) - x[side])) <= FILL_PX / 4 and
                    np.abs(np.median(x[a:b + 1] - np.polyval(fit, s[a:b + 1]))) > FILL_PX
                    and not _one_side(s, x, keep & (cut != cut[a]), a, b, 2 * h)):
                keep[a:b + 1] = alive[a:b + 1] = False
                dropped = True
            else:
                left.append((a, b))
        pieces = left
    return keep


def _one_side(s, x, others, a, b, reach) -> bool:
    """Whether the piece of centres a … b continues alone the centres of ``others`` ((n,)
    bool) within ``reach`` scan lines before it or those after it, where these two sides
    step apart: two parallel lines fitted, one through each side's centres (3/4 of them
    within FILL_PX / 2 of it: no step within a side, where a piece off the stripe could lie
    on some level), lie more than :data:`FILL_PX` apart, and the piece's median within
    FILL_PX of one. A line fitted across a step follows the side with more centres: at a
    board's edge in front of a wall the board's first piece, short before the first dark
    mark, lay on the wall's line (clipped_white spent seed 10004: 50 right columns dropped).
    s, x: (n,) scan line and cross coordinate."""
    before = others & (s < s[a]) & (s >= s[a] - reach)
    side = before | (others & (s > s[b]) & (s <= s[b] + reach))
    (k, c0, c1), *_ = np.linalg.lstsq(
        np.c_[s[side] - s[a], before[side], ~before[side]], x[side], rcond=None)
    res = np.abs(x[side] - k * (s[side] - s[a]) - np.where(before[side], c0, c1))
    if max(np.quantile(res[m], 0.75) for m in (before[side], ~before[side])) > FILL_PX / 2:
        return False
    piece = np.median(x[a:b + 1] - k * (s[a:b + 1] - s[a]))
    return bool(abs(c0 - c1) > FILL_PX and min(abs(piece - c0), abs(piece - c1)) <= FILL_PX)


def _sides(s, cut, a, b, h, alive):
    """The centres ``alive`` ((n,) bool) of other pieces than the piece of centres a … b
    within ``h`` scan lines of it ((n,) bool), and whether at least 3 lie on each side."""
    side = alive & (cut != cut[a]) & (np.abs(s - (s[a] + s[b]) / 2) <= (s[b] - s[a]) / 2 + h)
    return side, bool((side & (s < s[a])).sum() >= 3 and (side & (s > s[b])).sum() >= 3)
