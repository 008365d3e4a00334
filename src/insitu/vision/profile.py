"""A frame's values across a line, column by column, shared by the detection stage
(:mod:`insitu.vision.detect`) and the centre methods: the frame as an (H, W) array, its
saturation level and noise sigma, gathers of rows about each column's peak, and the peak's
background and width measured there."""

from __future__ import annotations

import cv2
import numpy as np

from insitu.vision.chains import leading, median3
from insitu.vision.laser_image import full_scale, read_window
from insitu.vision.noise_kernel import median_row_differences

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))


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


def frame_noise(img: np.ndarray, median: int = 3) -> float:
    """The noise sigma :func:`detect` measures on the median-filtered frame ``img`` (H, W)
    (any array, a transposed view too; ``median``: the methods' default pre-filter),
    from only the rows :func:`~insitu.vision.laser_image.noise_sigma` samples: each filtered
    with its own neighbours (3-row strips stacked; the frame's edges replicated, as
    medianBlur does), so a crop of the frame is measured with the whole frame's noise; only
    the part of the frame its camera read counts (:func:`~insitu.vision.laser_image.read_window`:
    a region of interest's frame is 0 outside it)."""
    img = read_window(img)
    H = img.shape[0]
    d = min(8, H - 1)
    if d < 1:
        return 0.0
    idx = np.arange(0, H - d, max(1, (H - d) // 32))
    if median == 3 and img.dtype in (np.uint8, np.uint16):      # the scan's frames: compiled
        return float(1.4826 / np.sqrt(2.0) * median_row_differences(img, idx, idx + d))
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
