"""The gaps of a photograph's stripe filled from the laser colour's excess over the other
channels (:func:`filled`): the excess's centres measured in windows round the gaps
(:func:`in_excess`) and added where they keep the stripe's course (:func:`fill_gaps`), in a
second pass with the dips at cores clipped in the laser's channel filled
(:func:`filled_cores`)."""

from __future__ import annotations

import inspect
from dataclasses import replace

import numpy as np

from insitu.vision.course import FIELDS, FILL_PX, kept
from insitu.vision.detect import LineCentres, detect
from insitu.vision.laser_image import CHANNELS, WHITE, LaserImage, colour_reach, excess
from insitu.vision.profile import frame_noise


def filled(c: LineCentres, li: LaserImage, fn, along_rows: bool, scaled,
           white: np.ndarray, run: int) -> LineCentres:
    """``c``, a photograph's centres in the laser's light ``li``, with the scan lines between
    its ends it has none on filled from the excess (:func:`in_excess`, :func:`fill_gaps`),
    then those left from the excess with the clipped cores' dips filled, where they fill
    ``run`` or more scan lines in a row. fn, scaled: :func:`in_excess`; white: (H, W) bool,
    all three channels clipped."""
    scan = c.u if along_rows else c.v
    if not 1 < len(c) < np.ptp(scan) + 1:                              # no gaps
        return c
    reach = colour_reach(li.gray.shape)[0]
    for cores in (False, True):
        c = fill_gaps(c, in_excess(li, c, fn, along_rows, scaled, cores), along_rows, white,
                      reach, run * cores)
    return c


def in_excess(li: LaserImage, c: LineCentres, fn, along_rows: bool, scaled,
              cores: bool) -> LineCentres:
    """``fn``'s centres in the laser channel's excess over the others round the gaps of the
    stripe's centres ``c``: in each window from a gap's last centre before to its first
    after, ± 4 × the colour's reach along and across (overlapping windows joined), measured
    in one pass over the windows side by side (:data:`_APART` scan lines between) with the
    whole excess's noise, each scan line's peak its brightest laser-coloured pixel (a window
    round a gap holds the stripe's colour and little else; cores: the dips at cores clipped
    in the laser's channel filled, :func:`filled_cores`). fn: a centre method's find;
    scaled(full_scale): its keywords for a frame of that full scale."""
    rows = along_rows
    scan, cross = (c.u, c.v) if rows else (c.v, c.u)
    order = np.argsort(scan, kind="stable")
    s, x = np.round(scan[order]).astype(np.int64), cross[order]
    ex, bgr, allow = ((excess(li), li.bgr, li.allow) if rows else                # (cross, scan)
                      (excess(li).T, li.bgr.transpose(1, 0, 2), li.allow.T))
    margin = 4 * colour_reach(ex.shape)[0]
    gap = np.flatnonzero(np.diff(s) > 1)
    windows = []
    for a, b in _joined(s[gap] - margin, s[gap + 1] + margin):
        near = (s >= a) & (s <= b)
        lo = max(int(x[near].min()) - margin, 0)
        hi = min(int(np.ceil(x[near].max())) + margin + 1, ex.shape[0])
        windows.append((max(a, 0), min(b + 1, ex.shape[1]), lo, hi))
    if not windows:
        return kept(c, slice(0))
    noise, kw = frame_noise(ex), scaled(li.full_scale)
    height = max(hi - lo for _, _, lo, hi in windows)
    at = np.cumsum([0] + [b - a + _APART for a, b, _, _ in windows])
    img = np.zeros((height, at[-1]), np.float32)
    ok = np.zeros((height, at[-1]), bool)
    for (a, b, lo, hi), k in zip(windows, at):
        img[:hi - lo, k:k + b - a] = filled_cores(
            ex[lo:hi, a:b], bgr[lo:hi, a:b], CHANNELS[li.channel], li.full_scale, kw,
            noise) if cores else ex[lo:hi, a:b]
        ok[:hi - lo, k:k + b - a] = allow[lo:hi, a:b]
    e = fn(img, band=None, allow=ok, **(kw | {"noise": noise, "ridge": False}))
    i = np.searchsorted(at, np.round(e.u), side="right") - 1
    start, top = np.array([w[0] for w in windows]), np.array([w[2] for w in windows])
    along, across = e.u - at[i] + start[i], e.v + top[i]
    return replace(e, u=along, v=across) if rows else replace(e, u=across, v=along)


_APART = 16
"""Blank scan lines between the windows of :func:`in_excess` (more than a line's track
carries across)."""


def _joined(starts: np.ndarray, ends: np.ndarray) -> list[tuple[int, int]]:
    """The windows [starts[i], ends[i]] (sorted by start) with those that overlap joined."""
    out: list[list[int]] = []
    for a, b in zip(starts.tolist(), ends.tolist()):
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


def fill_gaps(c: LineCentres, e: LineCentres, along_rows: bool, white: np.ndarray,
              reach: int, run: int = 0) -> LineCentres:
    """``c`` with the centres of ``e`` added on the scan lines ``c`` has none, between its
    ends, where they lie within :data:`FILL_PX` of ``c``'s course there (interpolated
    between its neighbours) and, where pixels of ``white`` ((H, W) bool: all three channels
    clipped) lie within ±``reach`` px across on their scan line, within FILL_PX of their
    middle. ``e``: the centres in the laser channel's excess over the others, where a neutral
    board's pattern cancels and a stripe running along a dark square's edge (a step in the
    channel, no peak) is a ridge; a core clipped white is a hole in that excess: a centre
    amid it is the hole's middle, one beside it its halo's flank (clipped_white spent seed
    10004: 49 columns filled 8.5 px off the line). run: the least number of consecutive
    scan lines the centres added fill (a core clipped along a stripe, not a lone scan line's
    glint or mark's rim), unless they fill a whole gap of ``reach`` or more scan lines, from
    the stripe's centre before it to the one after (a fill that splits a gap leaves runs
    shorter than ``run``: clipped_white spent seed 13005, 14 scan lines; across a shorter
    gap, between neighbours themselves off, a centre can lie over 5 px off)."""
    key = (lambda x: x.u) if along_rows else (lambda x: x.v)
    cross = (lambda x: x.v) if along_rows else (lambda x: x.u)
    sc, se = np.round(key(c)).astype(np.int64), np.round(key(e)).astype(np.int64)
    order = np.argsort(sc)
    course = np.interp(se, sc[order], cross(c)[order])
    add = ((se > sc.min()) & (se < sc.max()) & ~np.isin(se, sc)
           & (np.abs(cross(e) - course) <= FILL_PX)
           & ~(np.abs(_white_middle(e, white, reach, along_rows) - cross(e)) > FILL_PX))
    if run > 1 and add.any():
        lines = np.unique(se[add])
        part = np.r_[0, np.cumsum(np.diff(lines) > 1)]
        ends = np.flatnonzero(np.diff(part))
        first, last = lines[np.r_[0, ends + 1]], lines[np.r_[ends, len(lines) - 1]]
        whole = np.isin(first - 1, sc) & np.isin(last + 1, sc) & (last - first + 1 >= reach)
        add &= np.isin(se, lines[((np.bincount(part) >= run) | whole)[part]])
    if not add.any():
        return c
    keep = np.argsort(np.r_[sc, se[add]], kind="stable")
    return replace(c, **{f: np.r_[getattr(c, f), getattr(e, f)[add]][keep] for f in FIELDS})


def least_contrast(kw: dict, full_scale: float, noise: float) -> float:
    """The least contrast (gray values) :func:`~insitu.vision.detect.detect` takes for a
    peak with the keywords ``kw`` (its own defaults where they give none), a frame of
    ``full_scale`` and ``noise`` sigma."""
    d = {k: p.default for k, p in inspect.signature(detect).parameters.items()} | kw
    return max(d["min_contrast"] * full_scale / 255, d["snr"] * noise)


def filled_cores(ex: np.ndarray, bgr: np.ndarray, channel: int, full_scale: float, kw: dict,
                 noise: float) -> np.ndarray:
    """``ex`` (n, m) the laser's excess in ``bgr`` (n, m, 3), scan lines along axis 1, with
    the dips filled on the runs of pixels across the line where the laser's ``channel`` is
    at full scale (≥ :data:`~insitu.vision.laser_image.WHITE` × ``full_scale``) and the
    others are not (white: no excess left, a hole :func:`fill_gaps` takes the middle of).
    There the laser channel's light is read from the others' crosstalk: its value stays at
    full scale, the others rise with the light, and the excess dips at the core between two
    peaks at the run's flanks (clipped_white spent seed 13007: 123 at the core, 146 and 158
    some 3 px either side; the excess's centres went to a square's edge lit 9–13 px off).
    Each such pixel gets the lower of the greatest excess before it and after it on the
    run plus its dip below that (the dip mirrored: highest at the core), on runs whose dip
    is as deep as the least contrast of a peak (:func:`least_contrast`, the detection's
    keywords ``kw`` and the excess's ``noise``): a dip the detection resolves into two
    peaks. A bright square's edge lit by the halo has no such dip: it stays as it is."""
    level = WHITE * full_scale
    clip = (bgr[..., channel] >= level) & (bgr.min(axis=2) < level)
    if not clip.any():
        return ex
    x = ex.astype(np.float64)
    big = float(x.max()) + 1.0
    label = np.cumsum(~clip | np.r_[np.ones((1, clip.shape[1]), bool), ~clip[:-1]], axis=0)
    label += np.arange(clip.shape[1]) * (clip.shape[0] + 1)    # each scan line's apart
    up = np.maximum.accumulate(x + label * big, axis=0) - label * big
    down = (np.maximum.accumulate((x - label * big)[::-1], axis=0) + label[::-1] * big)[::-1]
    top = np.where(clip, np.minimum(up, down), x)
    dip = np.zeros(int(label.max()) + 1)
    np.maximum.at(dip, label, top - x)
    least = least_contrast(kw, full_scale, noise)
    return np.where(dip[label] >= least, 2 * top - x, x).astype(ex.dtype)


def _white_middle(c: LineCentres, white: np.ndarray, reach: int,
                  along_rows: bool) -> np.ndarray:
    """(n,) px across the line: the middle of the pixels of ``white`` (H, W) within
    ±``reach`` px of each centre of ``c`` on its scan line (NaN where there is none)."""
    g = white if along_rows else white.T
    s = np.clip(np.round(c.u if along_rows else c.v).astype(np.int64), 0, g.shape[1] - 1)
    x = np.round(c.v if along_rows else c.u).astype(np.int64)
    across = np.clip(x[None, :] + np.arange(-reach, reach + 1)[:, None], 0, g.shape[0] - 1)
    w = g[across, s[None, :]]
    lo = np.where(w, across, np.iinfo(np.int64).max).min(axis=0)
    hi = np.where(w, across, -1).max(axis=0)
    return np.where(w.any(axis=0), (lo + hi) / 2, np.nan)
