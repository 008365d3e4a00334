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
  (:mod:`insitu.vision.tracks`; photographs; False: the brightest pixel and ``continuity``);
  "alone": that track, or AmbiguousStripe where tracks beside it rival it.
* noise: the frame's noise sigma, gray values, when the image is a crop of a frame
  (:func:`~insitu.vision.profile.frame_noise`), so that a crop is measured with the frame's
  thresholds; None: the image's own.
* white: (H, W) bool, where a colour frame measured in the sum of its channels is clipped
  white in all three: a peak there needs min_contrast / 3 (≥ snr · noise): a halo clipping
  two channels leaves a white core standing out in the third only.
* quiet: (H, W) float32, within ``white``: the sum's noise as a fraction of ``noise``
  (≤ 1): where two of its channels are clipped they carry none, and it is the third's own. A
  halo that clips the laser's channel and lifts a second to full scale leaves the core's peak
  in the third only, over a sum as noisy as that channel, not as the three.

A stripe's clipped core is a plateau: its row is the plateau's middle, its background is
taken beyond the plateau, and the band the methods work in (``Detection.window``) grows by
half the longest plateaus, so that their flanks stay inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.vision.chains import carry_ends, junction, leading, short_ridges
from insitu.vision.chains import continuity as chain_support
from insitu.vision.detect_kernel import band_peaks, column_stats
from insitu.vision.laser_image import full_scale, noise_sigma
from insitu.vision.peak_rows import band_rows, peak_rows, search_rows, second_rows
from insitu.vision.profile import as_image, gather
from insitu.vision.tracks import candidates, on_longest_track

MIN_PEAK = 40.0
"""A peak's absolute floor, gray values of 255 (``min_peak``, scaled to the frame's full
scale)."""


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


def _stats(pre, row, w, cols):
    """Plateau-centred rows, peak, background, contrast and plateau length of the ridge
    candidates in columns ``cols`` (n,) with their peaks at ``row`` (n,) (the frame searched
    in its band alone: :func:`~insitu.vision.detect_kernel.column_stats`, whose background is
    the band's ends instead). Background: the mean of the least of the 3 px 1 to 3 px beyond
    each side's half maximum (its own sides); contrast: peak minus the brighter side's (an
    edge of a bright region is no line)."""
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
    wide = w + min(int(run.max(initial=0)) // 2, w)
    reach = _half_width(pre, row, gmax, wide, cols) + 1
    above, _ = gather(pre, row[None, :] - reach[None, :] + np.arange(3)[:, None], cols)
    below, _ = gather(pre, row[None, :] + reach[None, :] - np.arange(3)[:, None], cols)
    top, bot = above.min(axis=0), below.min(axis=0)
    return row, gmax, (top + bot) / 2, gmax - np.maximum(top, bot), run


def _half_width(pre, row, gmax, w, cols) -> np.ndarray:
    """(n,) int: how far from ``row`` each of the columns ``cols`` stays above half-way from
    the least of its ±w band to its peak, on the wider side, px."""
    g, inside = gather(pre, row[None, :] + np.arange(-w, w + 1)[:, None], cols)
    above = (g > (gmax + np.where(inside, g, np.inf).min(axis=0)) / 2) & inside
    up, down = leading(above[w::-1]), leading(above[w:])
    return np.minimum(np.maximum(up, down), w)


def detect(image, median=3, band=None, window=12, min_peak=MIN_PEAK, min_contrast=20.0,
           snr=6.0, continuity=True, max_jump=4.0, decisive=1.25,
           extend_ends=True, upper=0, *, scale=None, allow=None,
           min_run=0, ridge=False, noise=None, white=None, quiet=None) -> Detection:
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
        np.where(white, _white_floor(min_contrast, snr, noise, quiet), thr).astype(np.float32))
    compiled = allow is None and not ridge            # the band alone: compiled passes
    if compiled:
        lo, hi, searched, span = band_rows(pre.shape, band)
    else:
        search, lo, span, searched = search_rows(pre, band, allow, fill, w if ridge else 0,
                                                 least)
    def at(j, cols):                                 # the least contrast of peaks j, cols
        return least if white is None else least[cols, j]

    def candidate(j, cols=None):
        """Stats of the peaks at rows j of the columns ``cols`` (the tracks' candidates), or
        (None) of each column's peak j (W,), worked out only where that peak can pass."""
        if cols is not None:
            row, gmax, bg, contrast, run = _stats(pre, j, w, cols)
            ok = searched[cols] & (gmax >= min_peak) & (contrast >= at(j, cols))
            return row, gmax, bg, contrast, ok, run
        row, run, gmax, bg, contrast = column_stats(pre, j, w, searched, min_peak)
        ok = searched & (gmax >= min_peak) & (contrast >= at(j, np.arange(W)))
        return row, gmax, bg, contrast, ok, run

    if ridge:
        row, gmax, bg, contrast, ok, run, ambiguous = on_longest_track(
            candidates(search, fill, w, candidate), max_jump, ridge == "alone")
        locked = ambiguous
    else:
        if compiled:
            j1, second_peaks = band_peaks(pre, lo, hi, searched, fill)
        else:
            j1 = peak_rows(search, lo, fill)
        row, gmax, bg, contrast, ok, run = candidate(j1)
        ambiguous, locked = np.zeros(W, bool), np.zeros(W, bool)
    if not ridge and continuity and W > 2 and span > 2 * w + 1:
        live = gmax >= min_peak
        j2, found = (second_peaks(j1, w, live, min_peak) if compiled else
                     second_rows(search, j1, lo, fill, w, live, min_peak))
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


def _white_floor(min_contrast, snr, noise, quiet):
    """The least contrast of a peak where the frame is white: a third of min_contrast, not
    below snr times the noise, a share of it where ``quiet`` gives one (detect's keywords)."""
    if quiet is None:
        return max(min_contrast / 3, snr * noise)
    return np.maximum(min_contrast / 3, snr * noise * quiet)


def raw_saturated(img, det: Detection, sat: float) -> np.ndarray:
    g, _ = gather(img, det.row[None, :] + np.arange(-2, 3)[:, None], det.cols)
    return g.max(axis=0) >= sat if len(det.cols) else np.zeros(0, bool)


def _percentile90(a: np.ndarray) -> int:
    """int(np.percentile(a, 90)) of integers ``a`` (n ≥ 1,), from the two order statistics it
    lies between (numpy's linear method and its interpolation), without a full sort."""
    at = len(a) * 0.9 - 0.9
    i = int(np.floor(at))
    j = min(i + 1, len(a) - 1)
    part = np.partition(a, [i, j])
    lo, hi, frac = float(part[i]), float(part[j]), at - i
    return int(lo + (hi - lo) * frac if frac < 0.5 else hi - (hi - lo) * (1 - frac))


