"""A photograph's clipped core cut on one side by a dark mark's edge (:func:`cut_cores`).

Where the rim of a dark dot or square runs along the stripe within its clipped core, the
reflected light is the laser's times the albedo's step: the core stays clipped on the bright
side only, and every method's centre of that plateau lies up to ≈ 3 px on the bright side of
the line (benchmarks/clipped_white.py, tune seed 13). The plateau's bright end is still the
laser's own; the line lies half the stripe's clipped width, measured on its uncut scan lines
nearby, inside it. A clipped run as long as the profile read (:data:`REACH`) is a clipped
area, not a core.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from insitu.vision.detect import LineCentres

REACH = 20
"""Pixels either side of a centre its profile is read over."""
SIDE = 12
"""Distance (px) from a centre at which each side's background is read (3 px from there out)."""
STEP = 0.5
"""Least change of the background from one side of the core to the other, of the core's
height above the darker side, of a core cut by a mark's edge (tune seed 13: 0.07 in the
median on the board, 0.76–0.80 where the cores are cut; 5 % of the uncut ones beside a mark
reach 0.4–0.9, which the clipped width's shortfall, :data:`CUT_PX`, tells apart)."""
CUT_PX = 3.0
"""Least shortfall (px) of a core's clipped width against its uncut neighbours' of a core cut
by a mark's edge."""
NEAR = 60
"""Scan lines either side over which the uncut neighbours' clipped width is taken."""


def cut_cores(c: LineCentres, img: np.ndarray, level: float, along_rows: bool) -> LineCentres:
    """``c`` with the centres of clipped cores cut by a mark's edge (module docstring) moved to
    the plateau's bright end less half the median clipped width of the uncut cores within
    :data:`NEAR` scan lines. img: (H, W) the image the centres were measured in; level: the
    value from which a pixel counts as clipped; along_rows: the line runs along the rows
    (one centre per column). Centres with no uncut core near are left as they are."""
    if not len(c) or not c.saturated.any():
        return c
    g = img if along_rows else img.T
    scan, cross = (c.u, c.v) if along_rows else (c.v, c.u)
    s, x = np.round(scan).astype(np.int64), np.round(cross).astype(np.int64)
    d = np.arange(-REACH, REACH + 1)
    prof = g[np.clip(x[None] + d[:, None], 0, g.shape[0] - 1), s[None]].astype(np.float64)
    n = np.arange(len(s))
    mid = REACH - 2 + np.argmax(prof[REACH - 2:REACH + 3], axis=0)
    clip = prof >= level
    label = np.cumsum(~clip, axis=0)
    run = clip & (label == label[mid, n]) & clip[mid, n]
    lo_side = np.median(prof[REACH - SIDE - 2:REACH - SIDE + 1], axis=0)
    hi_side = np.median(prof[REACH + SIDE:REACH + SIDE + 3], axis=0)
    step = np.abs(hi_side - lo_side) / np.maximum(prof[mid, n] - np.minimum(lo_side, hi_side),
                                                  1e-9)
    idx = d[:, None]
    a, b = np.where(run, idx, REACH).min(axis=0), np.where(run, idx, -REACH).max(axis=0)
    top, bot = a - _beyond(prof, a - 1, a, level), b + _beyond(prof, b + 1, b, level)
    half = (bot - top) / 2
    core = run.any(axis=0) & ~run[0] & ~run[-1] & c.saturated      # not a clipped area
    even = core & (step <= STEP)
    near = np.full(len(s), np.nan)
    near[core & ~even] = _median_near(s[core & ~even], s[even], half[even])
    cut = core & ~even & (near - half >= CUT_PX / 2)
    if not cut.any():
        return c
    centre = np.where(hi_side > lo_side, bot - near, top + near)
    new = np.where(cut, x + centre, cross)
    return replace(c, v=new) if along_rows else replace(c, u=new)


def _beyond(prof: np.ndarray, out: np.ndarray, end: np.ndarray, level: float) -> np.ndarray:
    """(n,) how far past each clipped run's ``end`` row (an offset in ``prof`` (2·REACH + 1,
    n)) towards ``out`` its profile stays above ``level`` (linear between the two), 0…1."""
    n = np.arange(prof.shape[1])
    p_end = prof[np.clip(end + REACH, 0, 2 * REACH), n]
    p_out = prof[np.clip(out + REACH, 0, 2 * REACH), n]
    return np.clip((p_end - level) / np.maximum(p_end - p_out, 1e-9), 0.0, 1.0)


def _median_near(s: np.ndarray, at: np.ndarray, value: np.ndarray) -> np.ndarray:
    """(n,) per scan line ``s`` (n,), the median of ``value`` (m,) over the scan lines ``at``
    (m,) within :data:`NEAR` of it (NaN where none)."""
    order = np.argsort(at, kind="stable")
    at, val = at[order], value[order]
    lo, hi = np.searchsorted(at, s - NEAR), np.searchsorted(at, s + NEAR, side="right")
    return np.array([np.median(val[i:j]) if j > i else np.nan for i, j in zip(lo, hi)])
