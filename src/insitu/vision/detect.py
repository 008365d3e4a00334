"""The detection stage every line-centre method shares (:mod:`insitu.vision.centres`): median
pre-filter, peak row per column, validity test, choice between two separated peaks. Keywords:

* extend_ends: each run of valid columns carried on, column by column, while the line's
  peak filtered along the row at the row its slope predicts passes the same thresholds
  (:func:`carry_ends`): the square median halves the peak of a line 1–2 px wide, and a
  line's dimmer last columns would fail them. Columns carried on this way are ``carried``.
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
  rows (a small step), where they are one peak per column, by :func:`carry_ends`.
* saturation: gray value counted as saturated (None: the full scale; float frames: none).
* scale: the frame's full scale, 2^pixel_bits − 1 (a Mono12 camera's frames: 4095, in 16
  bits); None: the dtype's (:func:`~insitu.vision.laser_image.full_scale`). min_peak and
  min_contrast are fractions of it, written on the 8-bit scale: 40 is 40/255 of full scale,
  642 in a Mono12 frame — a scan measures alike at 8, 10, 12 or 16 bits.
* allow: (H, W) bool, where a peak may be taken (laser-coloured light within reach,
  :mod:`insitu.vision.laser_image`); None: everywhere.
* min_run: a ridge of fewer valid columns is no stripe (a glint, a lamp, a short edge):
  dropped (:func:`~insitu.vision.chains.short_ridges`; 0: none is).
* ridge: each column's candidates are its pixels on a ridge (its white top-hat over ±window
  rows passes the contrast threshold) brightest within ±window rows, and a peak's contrast is
  over its own sides (the least of 3 px just beyond its half maximum), not over the band's
  ends: a line on a black square beside a white one is a ridge, though the white square is
  brighter. Of a column's candidates the one on the longest track across the columns is kept
  (:mod:`insitu.vision.tracks`; photographs; False: the brightest pixel and ``continuity``).
* noise: the frame's noise sigma, gray values, when the image is a crop of a frame
  (:func:`frame_noise`), so that a crop is measured with the frame's thresholds; None: the
  image's own.
* white: (H, W) bool, where a colour frame measured in the sum of its channels is clipped
  white in all three: a peak there needs min_contrast / 3 (≥ snr · noise): a halo clipping
  two channels leaves a white core standing out in the third only.

A stripe's clipped core is a plateau: its row is the plateau's middle, its background is
taken beyond the plateau, and the band the methods work in (``Detection.window``) grows by
half the longest plateaus, so that their flanks stay inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.vision.chains import carry_ends, junction, leading, median3, short_ridges
from insitu.vision.chains import continuity as chain_support
from insitu.vision.laser_image import full_scale, noise_sigma
from insitu.vision.tracks import candidates, on_longest_track

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))


@dataclass(frozen=True)
class LineCentres:
    """Centres found in one frame; one per scan column at most, ordered by column.

    u, v: (N,) float64 px (image x = column, y = row). peak: (N,) gray value of the peak.
    width: (N,) px — pixels above the threshold (gray centroid) or FWHM (other methods).
    contrast: (N,) peak minus the local background on the brighter side (median of 3 px at
    ±window rows from the peak, median-filtered image), gray values. saturated: (N,) bool, the
    raw peak reached the sensor's saturation. ambiguous: (N,) bool, the column (inside the band,
    if one was given) had a second valid peak more than window rows away; continuity chose.
    full_scale: the frame's full scale in the same gray values (peak / full_scale: 0 … 1).
    """

    u: np.ndarray
    v: np.ndarray
    peak: np.ndarray
    width: np.ndarray
    contrast: np.ndarray
    saturated: np.ndarray | None = None
    ambiguous: np.ndarray | None = None
    full_scale: float = 255.0

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
    carried: (n,) the columns a line's end was carried on to (``extend_ends``). window: the
    half-band, rows, the methods work in (the given window, grown for long plateaus).
    full_scale: the frame's (gray values)."""

    cols: np.ndarray
    row: np.ndarray
    gmax: np.ndarray
    bg: np.ndarray
    contrast: np.ndarray
    ambiguous: np.ndarray
    pre: np.ndarray
    noise: float
    carried: np.ndarray
    window: int
    full_scale: float


def as_image(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"expected a non-empty (H, W) gray image, got shape {img.shape}")
    if img.dtype not in (np.uint8, np.uint16, np.float32):
        img = img.astype(np.uint8 if img.dtype == bool else np.float32)
    return np.ascontiguousarray(img)


def saturation_level(img: np.ndarray, saturation: float | None,
                     scale: float | None = None) -> float:
    """``saturation``, else the full scale (``scale``, or the dtype's) of an integer frame; a
    float frame has none."""
    if saturation is not None:
        return float(saturation)
    if img.dtype.kind != "u":
        return np.inf
    return float(scale) if scale is not None else full_scale(img.dtype)


def gather(img: np.ndarray, rows: np.ndarray, cols: np.ndarray):
    """img[rows, cols] as float32 (k, n) with rows (k, n) clipped, and the (k, n) inside mask
    (one take from the flattened image: a third of the time of a two-index gather)."""
    H, W = img.shape
    if rows.size and rows.min() >= 0 and rows.max() < H:             # the common case
        return img.reshape(-1).take(rows * W + cols).astype(np.float32), np.ones(rows.shape, bool)
    inside = (rows >= 0) & (rows < H)
    flat = np.clip(rows, 0, H - 1) * W + cols
    return img.reshape(-1).take(flat).astype(np.float32), inside


def _stats(pre, row, w, near=False, cols=None):
    """Plateau-centred rows, peak, background, contrast and plateau length of the columns
    ``cols`` (None: all) with their peaks at ``row`` (one per column).
    Background: the mean of the medians of 3 px at each end of the band ±w rows about it,
    widened by half of a plateau longer than 2 px (near: of the least of the 3 px 1 to 3 px
    beyond the line's half maximum, its own sides); contrast: peak minus the brighter side's
    (an edge of a bright region is no line)."""
    cols = np.arange(pre.shape[1]) if cols is None else cols
    below, inside = gather(pre, row[None, :] + np.arange(0, w + 1)[:, None], cols)
    gmax = below[0]
    same = (below == gmax) & inside
    run = np.where(same.all(axis=0), w + 1, np.argmin(same, axis=0))  # plateau from 1st max
    long = np.flatnonzero(run > w)                     # a clipped core: its whole plateau
    if len(long):
        far, inside = gather(pre, row[None, long] + np.arange(0, 4 * w + 1)[:, None],
                             cols[long])
        same = (far == gmax[long]) & inside
        run[long] = np.where(same.all(axis=0), 4 * w + 1, np.argmin(same, axis=0))
    row = row + (run - 1) // 2
    if near:
        wide = w + min(int(run.max(initial=0)) // 2, w)
        reach, pick = _half_width(pre, row, gmax, wide, cols) + 1, lambda a: a.min(axis=0)
    else:
        reach, pick = w + np.maximum(run - 2, 0) // 2, lambda a: median3(*a)
    above, _ = gather(pre, row[None, :] - reach[None, :] + np.arange(3)[:, None], cols)
    below, _ = gather(pre, row[None, :] + reach[None, :] - np.arange(3)[:, None], cols)
    top, bot = pick(above), pick(below)
    return row, gmax, (top + bot) / 2, gmax - np.maximum(top, bot), run


def _half_width(pre, row, gmax, w, cols) -> np.ndarray:
    """(n,) int: how far from ``row`` each of the columns ``cols`` stays above half-way from
    the least of its ±w band to its peak, on the wider side, px."""
    g, inside = gather(pre, row[None, :] + np.arange(-w, w + 1)[:, None], cols)
    above = (g > (gmax + np.where(inside, g, np.inf).min(axis=0)) / 2) & inside
    up, down = leading(above[w::-1]), leading(above[w:])
    return np.minimum(np.maximum(up, down), w)


def _search(pre, band, allow, fill, ridge, thr):
    """The (W, n) array of each column's candidate values at rows top … top + n − 1 (a
    copy, ours to overwrite): ``pre`` transposed, ``fill`` outside the column's band, where
    not allowed and (ridge > 0) where the column's white top-hat over 2·ridge + 1 rows stays
    below ``thr`` (or its (W, H) map); the first row of each column's band (W,), the most
    rows a band has, the searched columns (W,) bool, and top (the rows all bands span; 0,
    all rows, with allow or ridge)."""
    H, W = pre.shape
    lo, hi, searched, span = np.zeros(W, np.int64), None, np.ones(W, bool), H
    if band is not None:
        blo, bhi = (np.broadcast_to(np.asarray(b, np.float64), (W,)) for b in band)
        with np.errstate(invalid="ignore"):
            flo, fhi = np.ceil(blo), np.floor(bhi)
            searched = (np.isfinite(flo) & np.isfinite(fhi) & (flo <= fhi) & (flo <= H - 1)
                        & (fhi >= 0))
        lo = np.where(searched, np.clip(flo, 0, H - 1), 0).astype(np.int64)
        hi = np.where(searched, np.clip(fhi, 0, H - 1), -1).astype(np.int64)
        span = max(int((hi - lo).max()) if W else 0, 0) + 1
    top, bottom = 0, H
    if hi is not None and allow is None and not ridge and searched.any():
        top, bottom = int(lo[searched].min()), int(hi[searched].max()) + 1
    search = cv2.transpose(pre[top:bottom])
    blocked = None if allow is None else ~cv2.transpose(allow.astype(np.uint8)).astype(bool)
    if ridge:
        hat = cv2.morphologyEx(search, cv2.MORPH_TOPHAT, np.ones((1, 2 * ridge + 1), np.uint8),
                               borderType=cv2.BORDER_REPLICATE)
        blocked = hat < thr if blocked is None else blocked | (hat < thr)
    if hi is not None:
        dt = np.int16 if H < 2**15 else np.int64                 # the compares' speed
        rows = np.arange(top, bottom, dtype=dt)
        inside = (rows >= lo.astype(dt)[:, None]) & (rows <= hi.astype(dt)[:, None])
        if blocked is None and fill == 0:
            np.multiply(search, inside, out=search, casting="unsafe")
        else:
            blocked = ~inside if blocked is None else blocked | ~inside
    if blocked is not None:
        np.putmask(search, blocked, fill)
    return search, lo, span, searched, top


def _peak_rows(search, lo, fill, top):
    """Each column's row of its greatest candidate (the first of equals), or the first row of
    its band where it has none (all ``fill``); ``search``'s first row is ``top``."""
    j = np.argmax(search, axis=1)
    return np.where(search[np.arange(len(j)), j] == fill, lo, j + top)


def _second_rows(search, j1, lo, fill, top, w, live, min_peak):
    """:func:`_peak_rows` of ``search`` with each column's ±w rows about its first peak j1
    (W,) set to ``fill``, worked out only in the ``live`` columns (W,) bool (those whose first
    peak can pass) whose greatest value left reaches ``min_peak``; the first row of its band
    in every other column. Also (W,) bool: the columns worked out, the only ones whose
    second peak may pass (a band's first row can hold the first peak's flank)."""
    n = search.shape[1]
    out, cols = lo.copy(), np.flatnonzero(live)
    part = search[cols]
    guard = np.clip((j1[cols] - top)[:, None] + np.arange(-w, w + 1), 0, n - 1)
    part.reshape(-1)[guard + (np.arange(len(cols)) * n)[:, None]] = fill
    keep = part.max(axis=1, initial=fill) >= min_peak
    out[cols[keep]] = _peak_rows(part[keep], lo[cols[keep]], fill, top)
    found = np.zeros(len(lo), bool)
    found[cols[keep]] = True
    return out, found


def detect(image, median=3, band=None, window=12, min_peak=40.0, min_contrast=20.0,
           snr=6.0, continuity=True, max_jump=4.0, decisive=1.25,
           extend_ends=True, upper=0, *, scale=None, allow=None,
           min_run=0, ridge=False, noise=None, white=None) -> Detection:
    """Peak row per valid column of a line running along the rows (module docstring)."""
    img = as_image(image)
    fs = float(scale) if scale is not None else full_scale(img.dtype)
    min_peak, min_contrast = min_peak * fs / 255, min_contrast * fs / 255
    pre = cv2.medianBlur(img, median) if median and median > 1 else img
    H, W = pre.shape
    w = max(int(window or 12), 3)
    noise = noise_sigma(pre) if noise is None else float(noise)
    fill = np.iinfo(pre.dtype).min if pre.dtype.kind == "u" else -np.inf
    thr = max(min_contrast, snr * noise)
    least = thr if white is None else cv2.transpose(        # (W, H), as search is laid out
        np.where(white, max(min_contrast / 3, snr * noise), thr).astype(np.float32))
    search, lo, span, searched, top = _search(pre, band, allow, fill, w if ridge else 0, least)
    def at(j, cols):                                 # the least contrast of peaks j, cols
        return least if white is None else least[cols, j]

    def candidate(j, cols=None):
        """Stats of the peaks at rows j of the columns ``cols`` (the tracks' candidates), or
        (None) of each column's peak j (W,), worked out only where that peak can pass."""
        if cols is not None:
            row, gmax, bg, contrast, run = _stats(pre, j, w, ridge, cols)
            ok = searched[cols] & (gmax >= min_peak) & (contrast >= at(j, cols))
            return row, gmax, bg, contrast, ok, run
        out = [j.copy(), *np.zeros((3, W), np.float32), np.ones(W, np.int64)]
        cols = np.flatnonzero(searched & (pre.reshape(-1)[j * W + np.arange(W)] >= min_peak))
        for a, b in zip(out, _stats(pre, j[cols], w, ridge, cols)):
            a[cols] = b
        row, gmax, bg, contrast, run = out
        ok = searched & (gmax >= min_peak) & (contrast >= at(j, np.arange(W)))
        return row, gmax, bg, contrast, ok, run

    if ridge:
        row, gmax, bg, contrast, ok, run, ambiguous = on_longest_track(
            candidates(search, fill, w, candidate), max_jump)
        locked = ambiguous
    else:
        j1 = _peak_rows(search, lo, fill, top)
        row, gmax, bg, contrast, ok, run = candidate(j1)
        ambiguous, locked = np.zeros(W, bool), np.zeros(W, bool)
    if not ridge and continuity and W > 2 and span > 2 * w + 1:
        j2, found = _second_rows(search, j1, lo, fill, top, w, gmax >= min_peak, min_peak)
        row2, gmax2, bg2, contrast2, ok2, run2 = candidate(j2)
        ok2 &= found
        ambiguous = ok & ok2
        if ambiguous.any():
            s1, s2, lab1, lab2 = chain_support(row, row2, ok, ok2, contrast, contrast2,
                                               max_jump)
            step = ambiguous & junction(lab1, lab2, ok & ~ok2, ok2 & ~ok)
            locked = ambiguous & ~step
            second = (ambiguous & (s2 > s1) & ~step) | (step & (upper * (row2 - row) > 0))
            ok &= ~ambiguous | step | (np.maximum(s1, s2) >= decisive * np.minimum(s1, s2))
            pairs = ((row, row2), (gmax, gmax2), (bg, bg2), (contrast, contrast2), (run, run2))
            row, gmax, bg, contrast, run = (np.where(second, b, a) for a, b in pairs)
    if min_run > 1:
        ok &= ~short_ridges(ok, row, min_run, max_jump)
    carried = np.zeros(W, bool)
    if extend_ends and median and median > 1:
        was, before = ok, row
        ok, row, gmax, bg = carry_ends(img, ok, row, gmax, bg, min_peak, thr, searched,
                                       upper=upper, locked=locked)
        carried = ok & (~was | (row != before))
        contrast = np.where(carried, gmax - bg, contrast)
        run = np.where(carried, 1, run)
    cols = np.flatnonzero(ok)
    wide = max(_percentile90(run[cols]) - 2, 0) // 2 if len(cols) else 0
    return Detection(cols, row[ok], gmax[ok], bg[ok], contrast[ok], ambiguous[ok], pre, noise,
                     carried[ok], w + wide, fs)


def _percentile90(a: np.ndarray) -> int:
    """int(np.percentile(a, 90)) of integers ``a`` (n ≥ 1,), from the two order statistics it
    lies between (numpy's linear method and its interpolation), without a full sort."""
    at = len(a) * 0.9 - 0.9
    i = int(np.floor(at))
    j = min(i + 1, len(a) - 1)
    part = np.partition(a, [i, j])
    lo, hi, frac = float(part[i]), float(part[j]), at - i
    return int(lo + (hi - lo) * frac if frac < 0.5 else hi - (hi - lo) * (1 - frac))


def frame_noise(img: np.ndarray, median: int = 3) -> float:
    """The noise sigma :func:`detect` measures on the median-filtered frame ``img`` (H, W)
    (any array, a transposed view too; ``median``: the methods' default pre-filter),
    from only the rows :func:`~insitu.vision.laser_image.noise_sigma` samples: each filtered
    with its own neighbours (3-row strips stacked; the frame's edges replicated, as
    medianBlur does), so a crop of the frame is measured with the whole frame's noise."""
    H = img.shape[0]
    d = min(8, H - 1)
    if d < 1:
        return 0.0
    idx = np.arange(0, H - d, max(1, (H - d) // 32))
    rows = np.r_[idx, idx + d]
    if median and median > 1:
        h = median // 2
        strips = as_image(img[np.clip(rows[:, None] + np.arange(-h, h + 1), 0, H - 1).ravel()])
        rows_pre = cv2.medianBlur(strips, median)[h::2 * h + 1]
    else:
        rows_pre = as_image(img[rows])
    n = len(idx)
    if rows_pre.dtype.kind == "u":                     # integers: the median of a histogram
        diff = np.ascontiguousarray(cv2.absdiff(rows_pre[:n], rows_pre[n:])[:, ::2])
        counts = np.cumsum(cv2.calcHist([diff], [0], None, [256], [0, 256]).ravel().astype(
            np.int64) if diff.dtype == np.uint8 else np.bincount(diff.ravel()))
        m = counts[-1]
        mid = np.searchsorted(counts, [(m - 1) // 2, m // 2], side="right").mean()
    else:
        diff = rows_pre[:n, ::2].astype(np.float32) - rows_pre[n:, ::2].astype(np.float32)
        mid = np.median(np.abs(diff))
    return float(1.4826 / np.sqrt(2.0) * mid)


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


def fwhm(g, inside, base, gmax) -> np.ndarray:
    """Pixels of the (k, n) band centred on the peak that stand above half-way from ``base``
    (n,) (the brighter side's background) to the peak, contiguous with the band's middle: a
    FWHM in px. A bright area on one side of the line is not counted in its width."""
    above = (g > (base + gmax) / 2) & inside
    k = len(g) // 2
    up, down = leading(above[k::-1]), leading(above[k:])
    return np.maximum(up + down - 1, 0).astype(np.float64)
