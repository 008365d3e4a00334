"""Sub-pixel centres of a laser line that runs roughly along the image rows.

Gray centroid exactly as Li et al. §2.3: median filter, then per column the peak g_max, the
threshold K = k · g_max and the intensity-weighted centroid of the pixels above K (Eq. 7).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class LineCentres:
    """Centres found in one frame; one per image column at most.

    u, v: (N,) float64 px. peak: (N,) gray value of the column's peak. width: (N,) px above
    the threshold. contrast: (N,) peak minus the column's background estimate.
    """

    u: np.ndarray
    v: np.ndarray
    peak: np.ndarray
    width: np.ndarray
    contrast: np.ndarray

    def __len__(self) -> int:
        return len(self.u)

    @property
    def uv(self) -> np.ndarray:
        return np.column_stack([self.u, self.v])


def gray_centroid(image: np.ndarray, k: float = 0.5, min_peak: float = 40.0,
                  window: int | None = 12, median: int = 3) -> LineCentres:
    """Li et al.'s gray-centroid centres of a line running along the rows of ``image``.

    image: (H, W) uint8/uint16. k: threshold scale (0 < k < 1). min_peak: columns whose
    filtered peak is below this give no point. window: only pixels within ±window rows of the
    column's peak take part (None: the whole column, as the paper). median: aperture of the
    median pre-filter (0 or 1: none).
    """
    img = cv2.medianBlur(image, median) if median and median > 1 else image
    H, W = img.shape
    row = np.argmax(img, axis=0)                                   # (W,)
    cols = np.arange(W)
    gmax = img[row, cols].astype(np.float64)
    keep = gmax >= min_peak
    if window is None:
        band = img[:, keep].astype(np.float64)                     # (H, n)
        rows = np.arange(H, dtype=np.float64)[:, None]
        background = np.median(band, axis=0)
    else:
        offs = np.arange(-window, window + 1)[:, None]
        rows_i = np.clip(row[keep][None, :] + offs, 0, H - 1)      # (2w+1, n)
        band = img[rows_i, cols[keep][None, :]].astype(np.float64)
        rows = rows_i.astype(np.float64)
        background = np.minimum(band[0], band[-1])
    K = k * gmax[keep]
    g = np.where(band > K, band, 0.0)
    total = g.sum(axis=0)
    v = (g * rows).sum(axis=0) / np.where(total > 0, total, 1.0)
    width = (g > 0).sum(axis=0).astype(np.float64)
    return LineCentres(u=cols[keep].astype(np.float64), v=v, peak=gmax[keep], width=width,
                       contrast=gmax[keep] - background)
