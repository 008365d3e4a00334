"""Chains of peaks across scan columns, for the detection stage (:mod:`insitu.vision.detect`):
which of two candidate peaks of a column lies on the better supported chain (``continuity``),
where one line ends and another begins (``junction``), carrying a line's dim ends on
(``carry_ends``), and dropping ridges too short to be a stripe (``short_ridges``).
"""

from __future__ import annotations

import numpy as np

from insitu.vision.detect_kernel import carry, chain_labels, junction_columns

OWN_COLUMNS = 8
"""Columns of its own (no second peak there) that make a chain a line, not a ghost's tail."""


def median_of(x: np.ndarray) -> float:
    """np.median of a 1-D array without NaN (n ≥ 1), from the one or two order statistics
    it is: the same value, without np.median's overhead on a line's thousand values."""
    n = len(x)
    if n % 2:
        return float(np.partition(x, n // 2)[n // 2])
    part = np.partition(x, [n // 2 - 1, n // 2])
    return float(np.mean(part[n // 2 - 1:n // 2 + 1]))


def leading(mask: np.ndarray) -> np.ndarray:
    """(n,) int: how many of the first rows of each column of ``mask`` (k, n) bool are all
    True (np.logical_and.accumulate(mask, axis=0).sum(axis=0), by one arg-max)."""
    first = np.argmax(~mask, axis=0)
    return np.where(mask.all(axis=0), len(mask), first)


def median3(a, b, c):
    """The element-wise median of three arrays."""
    return np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))


def continuity(v1, v2, ok1, ok2, weight1, weight2, max_jump):
    """(W,) supports of the chains of peaks the first and the second candidate of each column
    belong to (0 where a candidate is not valid).

    Chains link candidates of columns 1 or 2 apart whose rows differ ≤ max_jump px per column;
    a chain's support is the summed contrast of its members. Also the chain labels (W,) of
    the first and second candidates.
    """
    W = len(v1)
    V = np.concatenate((v1, v2)).astype(np.float64)
    OK, Wt = np.concatenate((ok1, ok2)), np.concatenate((weight1, weight2))
    lab = chain_labels(V, OK, float(max_jump))
    support = np.bincount(lab[OK], weights=Wt[OK], minlength=2 * W)
    return (np.where(ok1, support[lab[:W]], 0.0), np.where(ok2, support[lab[W:]], 0.0),
            lab[:W], lab[W:])


def junction(lab1, lab2, own1, own2) -> np.ndarray:
    """(W,) bool: columns where one candidate's chain has at least ``OWN_COLUMNS`` columns of
    its own (``own1``, ``own2``: where only the first or the second candidate is valid), all
    before the column, and the other's as many, all after it — one line ends and the next
    begins there, as at a step. A ghost has few columns of its own, or lies within the real
    line's span, which then has own columns on both sides."""
    return junction_columns(lab1, lab2, own1, own2, OWN_COLUMNS)


RUN = 4
"""Valid columns in a row that make a line whose ends :func:`carry_ends` carries on."""
SHARED = 3
"""Columns past a top's end the lower line's blurred start may share with it."""


def carry_ends(img: np.ndarray, ok: np.ndarray, row: np.ndarray, gmax: np.ndarray,
               bg: np.ndarray, min_peak: float, thr: float, searched: np.ndarray,
               steps: int = 8, upper: int = 0, locked: np.ndarray | None = None
               ) -> tuple[np.ndarray, ...]:
    """(ok, row, gmax, bg) (W,) with each run of valid columns carried on, up to ``steps``
    columns each way, while the median of 3 px along the row of ``img`` (H, W) — which keeps
    a thin line's peak — stands ≥ ``min_peak`` and ≥ ``thr`` above the run's background at
    the row the line's slope in the frame predicts (± 1): a line's end columns, which the
    square median dims below the thresholds; nothing starts away from a line (a run of at
    least :data:`RUN` columns). A column another line holds is carried into (its first
    :data:`SHARED` columns) only when that line lies more than 2 px on the lower side
    (``upper``, module docstring) and the column is not ``locked`` (W,) — where the
    continuity of two peaks chose, a ghost beside the line does not take it back."""
    ok, row = ok.copy(), row.copy()
    gmax, bg = gmax.astype(np.float64), bg.astype(np.float64)
    locked = np.zeros(len(ok), bool) if locked is None else locked
    carry(img, ok, row, gmax, bg, float(min_peak), float(thr), searched, steps, upper, locked,
          RUN, SHARED)
    return ok, row, gmax, bg


def ridges_of(cols: np.ndarray, row: np.ndarray, bridge: int, max_jump: float) -> np.ndarray:
    """(n,) ridge label of each point (``cols`` (n,) increasing, ``row`` (n,)): points at most
    2 columns apart whose rows differ by at most ``max_jump`` px per column are linked, and a
    ridge carries on across a gap of up to ``bridge`` columns where it goes on within
    ``max_jump`` plus a tenth of the gap of where the frame's slope (the median step between
    neighbouring columns) puts it."""
    if not len(cols):
        return np.zeros(0, np.int64)
    gap, step = np.diff(cols), np.diff(np.asarray(row, np.float64))
    slope = float(np.median(step[gap == 1])) if (gap == 1).any() else 0.0
    tol = max_jump * np.minimum(gap, 2) + 0.1 * np.maximum(gap - 2, 0)
    off = np.where(gap <= 2, np.abs(step), np.abs(step - slope * gap))
    return np.r_[0, np.cumsum((gap > bridge) | (off > tol))]


def short_ridges(ok: np.ndarray, row: np.ndarray, min_run: int, max_jump: float) -> np.ndarray:
    """(W,) bool: the valid columns (``ok``) on ridges (:func:`ridges_of`, bridging gaps of up
    to 4 · min_run columns: a stripe lost on a black square, a dark speckle blotch) of fewer
    than ``min_run`` columns. A stripe crosses many columns; a glint, a lamp or a short edge
    a few."""
    cols = np.flatnonzero(ok)
    out = np.zeros(len(ok), bool)
    if min_run <= 1 or not len(cols):
        return out
    label = ridges_of(cols, row[cols], 4 * min_run, max_jump)
    out[cols] = np.bincount(label)[label] < min_run
    return out


def longest_ridge(u: np.ndarray, v: np.ndarray, bridge: int = 80, max_jump: float = 4.0) -> int:
    """Points on the longest ridge (:func:`ridges_of`) of centres ``u``, ``v`` (n,) px, one
    per scan column ``u``."""
    if not len(u):
        return 0
    order = np.argsort(u, kind="stable")
    return int(np.bincount(ridges_of(np.round(u[order]).astype(np.int64), v[order], bridge,
                                     max_jump)).max())
