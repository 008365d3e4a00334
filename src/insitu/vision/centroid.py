"""Gray-centroid centres of a laser line (Li et al. §2.3, Eq. 7), or above each column's local
background; one of the methods of :data:`~insitu.vision.centres.CENTRE_METHODS`, on the
detection stage of :mod:`insitu.vision.detect`."""

from __future__ import annotations

import cv2
import numpy as np

from insitu.vision.detect import MIN_PEAK, LineCentres, detect, raw_saturated
from insitu.vision.profile import as_image, band_background, fwhm, gather, saturation_level


def gray_centroid(image: np.ndarray, k: float = 0.5, min_peak: float = MIN_PEAK,
                  window: int | None = 12, median: int = 3, *, band=None,
                  min_contrast: float = 20.0, snr: float = 6.0, continuity: bool = True,
                  saturation: float | None = None, subtract: bool = False,
                  background: bool = False, extend_ends: bool = True,
                  upper: int = 0, scale: float | None = None, allow=None,
                  min_run: int = 0, ridge: bool = False,
                  noise: float | None = None, white=None, quiet=None) -> LineCentres:
    """Gray-centroid centres of a line running along the rows: Li et al.'s (§2.3, Eq. 7), or
    above the local background.

    image: (H, W) uint8/uint16/float32. k: threshold scale, K = k · g_max (0 < k < 1).
    min_peak: absolute floor of the filtered peak. window: only pixels within ±window rows of
    the peak (None: the whole column as the paper, so a ghost above K counts too). median:
    aperture of the median pre-filter (0 or 1: none). Keywords: :mod:`insitu.vision.detect`.
    width: px above K.
    subtract: weights g_i − K instead of Eq. 7's g_i (not the paper; removes most of Eq. 7's
    phase-dependent bias of ≈ 0.15 px at k = 0.3, which comes from pixels entering the sum
    with weight K as the line moves).
    background: K above the column's local background (:func:`_above_background`; window
    None: K = bg + k · (g_max − bg), bg the detection's), weights g_i − K (``subtract``
    implied): a bright or sloping surface under the line, or a bright area beside it, no
    longer enters the sum. False: Eq. 7, the paper mode that
    :data:`~insitu.vision.extract.PAPER_SETTINGS` reproduces.
    """
    img = as_image(image)
    det = detect(img, median, band, window, min_peak, min_contrast, snr, continuity,
                 extend_ends=extend_ends, upper=upper, scale=scale, allow=allow,
                 min_run=min_run, ridge=ridge, noise=noise, white=white, quiet=quiet)
    c, r, gmax = det.cols, det.row, det.gmax
    level = saturation_level(img, saturation, scale)
    if background and window is not None:
        return _above_background(img, det, k, level)
    K = (det.bg + k * (gmax - det.bg) if background else k * gmax).astype(np.float32)
    subtract = subtract or background
    if window is None:                                             # whole columns, (n, H)
        g = cv2.transpose(det.pre)[c].astype(np.float32)
        g[g <= K[:, None]] = 0
        width = (g > 0).sum(axis=1).astype(np.float64)
        if subtract:
            g = np.where(g > 0, g - K[:, None], 0)
        total = g.sum(axis=1, dtype=np.float64)
        v = (g @ np.arange(img.shape[0], dtype=np.float32)) / np.where(total > 0, total, 1)
    else:
        window = det.window
        rows = np.arange(-window, window + 1)[:, None]
        g, inside = gather(det.pre, r[None, :] + rows, c)
        g[(g <= K) | ~inside] = 0
        width = (g > 0).sum(axis=0).astype(np.float64)
        if subtract:
            g = np.where(g > 0, g - K, 0)
        total = g.sum(axis=0, dtype=np.float64)
        v = r + (g * rows).sum(axis=0, dtype=np.float64) / np.where(total > 0, total, 1)
    return LineCentres(c.astype(np.float64), v.astype(np.float64), gmax.astype(np.float64),
                       width, det.contrast.astype(np.float64), raw_saturated(img, det, level),
                       det.ambiguous, det.full_scale)


def _above_background(img, det, k, level) -> LineCentres:
    """Gray centroid above the local background of each column (see gray_centroid): the
    band's background, running linearly between the medians of the 3 px at each end of the
    ±window band, taken away; then K = base + k · (peak − base), base the brighter of the two
    sides just off the line (d = FWHM/2 + 1 px from the peak, ≥ 0); weights g − K over the
    pixels above K contiguous with the peak. A bright area beside the line (a white square
    beside a black one, a lit top beside a dark wall) neither lowers K nor enters the sum."""
    c, r, gmax, w = det.cols, det.row, det.gmax, det.window
    rows = np.arange(-w, w + 1)[:, None]
    g, inside = gather(det.pre, r[None, :] + rows, c)
    d = np.clip(np.ceil(fwhm(g, inside, gmax - det.contrast, gmax) / 2) + 1, 2, w - 3)
    h = g - band_background(g)
    side = np.take_along_axis(h, (w + np.stack([-d, d])).astype(np.int64), axis=0)
    base = np.maximum(side.max(axis=0), 0)
    h -= base + k * (h[w] - base)
    above = (h > 0) & inside
    near = np.r_[np.cumprod(above[w::-1], axis=0)[::-1][:-1], np.cumprod(above[w:], axis=0)]
    h = np.where(near.astype(bool), h, 0)
    total = h.sum(axis=0, dtype=np.float64)
    v = r + (h * rows).sum(axis=0, dtype=np.float64) / np.where(total > 0, total, 1)
    return LineCentres(c.astype(np.float64), v, gmax.astype(np.float64),
                       (h > 0).sum(axis=0).astype(np.float64), det.contrast.astype(np.float64),
                       raw_saturated(img, det, level), det.ambiguous, det.full_scale)
