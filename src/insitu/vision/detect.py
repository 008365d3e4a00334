"""The detection stage every line-centre method shares (:mod:`insitu.vision.centres`): median
pre-filter, the peak row per column, a validity test, and a choice between two separated
peaks. Common keyword arguments of the methods:

* extend_ends: each run of valid columns carried on, column by column, while the line's
  peak filtered along the row at the row its slope predicts passes the same thresholds
  (:func:`carry_ends`): the square median halves the peak of a line 1–2 px wide (binning 2:
  39 for a raw 98), and a line's dimmer last columns failed them — its ends came up to 6 px
  short of the edge it leaves. Columns carried on this way are ``carried``.
* band: (v_lo, v_hi), each (W,) or scalar — rows allowed per column, e.g. the light plane's
  expected band from the geometry; NaN: the column is not searched.
* min_peak: absolute floor, gray values; min_contrast, snr: least peak − background, and least
  multiple of the frame's noise sigma. A column gives a point only when its peak ≥ min_peak AND
  its contrast ≥ max(min_contrast, snr · noise) — noise and edges of bright areas make none.
* continuity: where a column has a second valid peak > window rows from the first (ghost,
  secondary reflection), keep the one on the better supported chain of peaks across columns
  (rows ≤ 4 px apart per column; support = summed contrast), and only when that chain has at
  least ``decisive`` times the other's support (1.25: well beyond the few per cent by which
  speckle moves the support of a chain of a few dozen columns): a column that stays ambiguous
  gives no point rather than a guess. Where one chain's own columns (no second peak there)
  all lie before the column and the other's all after it, at least ``OWN_COLUMNS`` each — a
  line ending at a step and the lower line beginning, overlapping for a few columns — both
  are real: the peak on the higher surface's side is kept (``upper``), else the brighter
  (the longer chain would cut every top's end there). Points kept this way are ``ambiguous``.
* upper: +1 when a higher surface puts the line at larger rows, −1 at smaller, 0 unknown.
  Where a top's line ends at a step and the lower line begins, their columns overlap by the
  blur of the lower line's start; the top's end is what locates the edge, so the shared
  columns go to the line on the higher side — also when the two lie closer than ``window``
  rows (a small step), where they are one peak per column, by :func:`carry_ends`. The
  brighter peak lost a step block's top one or two columns at its step walls when the lower
  line began first in the image (its samples 0.15–0.26 mm inside those edges at binning 2).
* saturation: gray value counted as saturated (None: the dtype's maximum).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))
OWN_COLUMNS = 8
"""Columns of its own (no second peak there) that make a chain a line, not a ghost's tail."""


@dataclass(frozen=True)
class LineCentres:
    """Centres found in one frame; one per scan column at most, ordered by column.

    u, v: (N,) float64 px (image x = column, y = row). peak: (N,) gray value of the peak.
    width: (N,) px — pixels above the threshold (gray centroid) or FWHM (other methods).
    contrast: (N,) peak minus the local background on the brighter side (median of 3 px at
    ±window rows from the peak, median-filtered image), gray values. saturated: (N,) bool, the
    raw peak reached the sensor's saturation. ambiguous: (N,) bool, the column (inside the band,
    if one was given) had a second valid peak more than window rows away; continuity chose.
    """

    u: np.ndarray
    v: np.ndarray
    peak: np.ndarray
    width: np.ndarray
    contrast: np.ndarray
    saturated: np.ndarray | None = None
    ambiguous: np.ndarray | None = None

    def __post_init__(self):
        for name in ("saturated", "ambiguous"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(len(self.u), bool))

    def __len__(self) -> int:
        return len(self.u)

    @property
    def uv(self) -> np.ndarray:
        """(N, 2) float64 px."""
        return np.column_stack([self.u, self.v])


@dataclass
class Detection:
    """Detection result for the n valid columns: cols, row (int, plateau-centred), gmax, bg,
    contrast, ambiguous: (n,). pre: the filtered image. noise: its noise sigma (gray values).
    carried: (n,) the columns a line's end was carried on to (``extend_ends``)."""

    cols: np.ndarray
    row: np.ndarray
    gmax: np.ndarray
    bg: np.ndarray
    contrast: np.ndarray
    ambiguous: np.ndarray
    pre: np.ndarray
    noise: float
    carried: np.ndarray


def as_image(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"expected a non-empty (H, W) gray image, got shape {img.shape}")
    if img.dtype not in (np.uint8, np.uint16, np.float32):
        img = img.astype(np.uint8 if img.dtype == bool else np.float32)
    return np.ascontiguousarray(img)


def saturation_level(img: np.ndarray, saturation: float | None) -> float:
    if saturation is not None:
        return float(saturation)
    return float(np.iinfo(img.dtype).max) if img.dtype.kind == "u" else np.inf


def gather(img: np.ndarray, rows: np.ndarray, cols: np.ndarray):
    """img[rows, cols] as float32 (k, n) with rows (k, n) clipped, and the (k, n) inside mask."""
    H = img.shape[0]
    inside = (rows >= 0) & (rows < H)
    return img[np.clip(rows, 0, H - 1), cols].astype(np.float32), inside


def _noise(pre: np.ndarray) -> float:
    """Robust noise sigma (gray values) from differences of rows 8 apart, ≤ 32 row pairs."""
    H = pre.shape[0]
    d = min(8, H - 1)
    if d < 1:
        return 0.0
    idx = np.arange(0, H - d, max(1, (H - d) // 32))
    diff = pre[idx, ::2].astype(np.float32) - pre[idx + d, ::2].astype(np.float32)
    return float(1.4826 / np.sqrt(2.0) * np.median(np.abs(diff)))


def median3(a, b, c):
    """The element-wise median of three arrays."""
    return np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))


def _stats(pre, row, w):
    """Plateau-centred rows, peak, background and contrast for all columns. Background: the
    mean of the medians of 3 px at each end of the ±w band; contrast: peak minus the brighter
    end's (an edge of a bright region is no line)."""
    cols = np.arange(pre.shape[1])
    below, inside = gather(pre, row[None, :] + np.arange(0, w + 1)[:, None], cols)
    gmax = below[0]
    same = (below == gmax) & inside
    run = np.where(same.all(axis=0), w + 1, np.argmin(same, axis=0))  # plateau from 1st max
    row = row + (run - 1) // 2
    above, _ = gather(pre, row[None, :] + np.arange(-w, -w + 3)[:, None], cols)
    below, _ = gather(pre, row[None, :] + np.arange(w - 2, w + 1)[:, None], cols)
    (a0, a1, a2), (b0, b1, b2) = above, below
    top, bot = median3(a0, a1, a2), median3(b0, b1, b2)
    return row, gmax, (top + bot) / 2, gmax - np.maximum(top, bot)


def _continuity(v1, v2, ok1, ok2, weight1, weight2, max_jump):
    """(W,) supports of the chains of peaks the first and the second candidate of each column
    belong to (0 where a candidate is not valid).

    Chains link candidates of columns 1 or 2 apart whose rows differ ≤ max_jump px per column;
    a chain's support is the summed contrast of its members. Also the chain labels (W,) of
    the first and second candidates.
    """
    W = len(v1)
    V, OK, Wt = np.r_[v1, v2].astype(np.float64), np.r_[ok1, ok2], np.r_[weight1, weight2]
    src, dst = [], []
    for d in (1, 2):
        for s in (0, W):
            for t in (0, W):
                a, b = s + np.arange(W - d), t + np.arange(d, W)
                m = OK[a] & OK[b] & (np.abs(V[a] - V[b]) <= max_jump * d)
                src.append(a[m])
                dst.append(b[m])
    src, dst = np.concatenate(src), np.concatenate(dst)
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(2 * W, 2 * W))
    n, lab = connected_components(graph, directed=False)
    support = np.bincount(lab[OK], weights=Wt[OK], minlength=n)
    return (np.where(ok1, support[lab[:W]], 0.0), np.where(ok2, support[lab[W:]], 0.0),
            lab[:W], lab[W:])


def _junction(lab1, lab2, own1, own2) -> np.ndarray:
    """(W,) bool: columns where one candidate's chain has at least ``OWN_COLUMNS`` columns of
    its own (``own1``, ``own2``: where only the first or the second candidate is valid), all
    before the column, and the other's as many, all after it — one line ends and the next
    begins there, as at a step. A ghost has few columns of its own, or lies within the real
    line's span, which then has own columns on both sides."""
    W = len(lab1)
    cols = np.arange(W)
    lo, hi, n = np.full(2 * W, W), np.full(2 * W, -1), np.zeros(2 * W, int)
    for lab, own in ((lab1, own1), (lab2, own2)):
        np.minimum.at(lo, lab[own], cols[own])
        np.maximum.at(hi, lab[own], cols[own])
        np.add.at(n, lab[own], 1)
    a, b = lab1, lab2
    line = (n[a] >= OWN_COLUMNS) & (n[b] >= OWN_COLUMNS)
    return line & (((hi[a] < cols) & (lo[b] > cols)) | ((hi[b] < cols) & (lo[a] > cols)))


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
    H, W = img.shape
    cols = np.flatnonzero(ok)
    if len(cols) < 2:
        return ok, row, gmax, bg
    near = np.diff(cols) == 1
    slope = float(np.median(np.diff(row[cols])[near])) if near.any() else 0.0
    gap = (np.diff(cols) > 1) | (np.abs(np.diff(row[cols]) - slope) > 2)  # or a step
    first, last = cols[np.r_[True, gap]], cols[np.r_[gap, True]]
    line = last - first + 1 >= RUN                     # a stray column or two is no line
    fronts = [(c, -1) for c in first[line]] + [(c, 1) for c in last[line]]
    for end, d in fronts:
        for k in range(1, steps + 1):
            c = end + d * k
            if not 0 <= c < W or not searched[c]:
                break
            at = row[end] + slope * d * k
            if ok[c] and not (k <= SHARED and upper * (row[c] - at) < -2.0
                              and (locked is None or not locked[c])):
                break
            rr = np.clip(int(round(at)) + np.arange(-1, 2), 0, H - 1)
            a, b, e = (img[rr, min(max(x, 0), W - 1)].astype(np.float64)
                       for x in (c - 1, c, c + 1))
            v = median3(a, b, e)
            j = int(np.argmax(v))
            if v[j] < min_peak or v[j] - bg[end] < thr:
                break
            ok[c], row[c], gmax[c], bg[c] = True, rr[j], v[j], bg[end]
    return ok, row, gmax, bg


def detect(image, median=3, band=None, window=12, min_peak=40.0, min_contrast=20.0,
            snr=6.0, continuity=True, max_jump=4.0, decisive=1.25,
            extend_ends=True, upper=0) -> Detection:
    """Peak row per valid column of a line running along the rows (module docstring)."""
    img = as_image(image)
    pre = cv2.medianBlur(img, median) if median and median > 1 else img
    H, W = pre.shape
    w = max(int(window or 12), 3)
    noise = _noise(pre)
    fill = np.iinfo(pre.dtype).min if pre.dtype.kind == "u" else -np.inf
    search = cv2.transpose(pre)                          # (W, H) contiguous; ours to overwrite
    lo = np.zeros(W, np.int64)
    searched = np.ones(W, bool)
    if band is not None:
        blo, bhi = (np.broadcast_to(np.asarray(b, np.float64), (W,)) for b in band)
        with np.errstate(invalid="ignore"):
            flo, fhi = np.ceil(blo), np.floor(bhi)
            searched = (np.isfinite(flo) & np.isfinite(fhi) & (flo <= fhi) & (flo <= H - 1)
                        & (fhi >= 0))
        lo = np.where(searched, np.clip(flo, 0, H - 1), 0).astype(np.int64)
        hi = np.where(searched, np.clip(fhi, 0, H - 1), 0).astype(np.int64)
        span = np.arange(int((hi - lo).max()) + 1 if W else 1)
        idx = lo[:, None] + span[None, :]
        search = np.take_along_axis(search, np.minimum(idx, H - 1), axis=1)
        search[idx > hi[:, None]] = fill
    thr = max(min_contrast, snr * noise)

    def candidate(j):
        row, gmax, bg, contrast = _stats(pre, lo + j, w)
        return row, gmax, bg, contrast, searched & (gmax >= min_peak) & (contrast >= thr)

    j1 = np.argmax(search, axis=1)
    row, gmax, bg, contrast, ok = candidate(j1)
    ambiguous, locked = np.zeros(W, bool), np.zeros(W, bool)
    if continuity and W > 2 and search.shape[1] > 2 * w + 1:
        guard = np.clip(j1[:, None] + np.arange(-w, w + 1)[None, :], 0, search.shape[1] - 1)
        np.put_along_axis(search, guard, fill, axis=1)
        row2, gmax2, bg2, contrast2, ok2 = candidate(np.argmax(search, axis=1))
        ambiguous = ok & ok2
        if ambiguous.any():
            s1, s2, lab1, lab2 = _continuity(row, row2, ok, ok2, contrast, contrast2, max_jump)
            step = ambiguous & _junction(lab1, lab2, ok & ~ok2, ok2 & ~ok)
            locked = ambiguous & ~step
            second = (ambiguous & (s2 > s1) & ~step) | (step & (upper * (row2 - row) > 0))
            ok &= ~ambiguous | step | (np.maximum(s1, s2) >= decisive * np.minimum(s1, s2))
            pairs = ((row, row2), (gmax, gmax2), (bg, bg2), (contrast, contrast2))
            row, gmax, bg, contrast = (np.where(second, b, a) for a, b in pairs)
    carried = np.zeros(W, bool)
    if extend_ends and median and median > 1:
        was, before = ok, row
        ok, row, gmax, bg = carry_ends(img, ok, row, gmax, bg, min_peak, thr, searched,
                                       upper=upper, locked=locked)
        carried = ok & (~was | (row != before))
        contrast = np.where(carried, gmax - bg, contrast)
    cols = np.flatnonzero(ok)
    return Detection(cols, row[ok], gmax[ok], bg[ok], contrast[ok], ambiguous[ok], pre, noise,
                     carried[ok])


def raw_saturated(img, det: Detection, sat: float) -> np.ndarray:
    g, _ = gather(img, det.row[None, :] + np.arange(-2, 3)[:, None], det.cols)
    return g.max(axis=0) >= sat if len(det.cols) else np.zeros(0, bool)


def band_background(g: np.ndarray) -> np.ndarray:
    """(k, n) background under each column of a (k, n) band of rows centred on the peak: a
    straight line between the medians of the 3 px at each end. Beside a wall or the edge of a
    part the two sides of the line differ (a lit top on one, a dark face on the other); one
    level for both would leave a pedestal on one flank and cut the other."""
    (a0, a1, a2), (b0, b1, b2) = g[:3], g[-3:]
    top, bot = median3(a0, a1, a2), median3(b0, b1, b2)
    half = (len(g) - 1) / 2
    return (top + bot) / 2 + (bot - top) / (2 * half) * (np.arange(len(g)) - half)[:, None]


def fwhm(g, inside, bg, gmax) -> np.ndarray:
    """Pixels of the (k, n) band above half the contrast: a FWHM in px."""
    return ((g > (bg + gmax) / 2) & inside).sum(axis=0).astype(np.float64)
