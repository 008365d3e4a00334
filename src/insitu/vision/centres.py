"""Sub-pixel centres of a laser line: one crossing per scan column (rows mode) or per row, by
one of the methods of :data:`CENTRE_METHODS`.

Every method uses the detection stage and keywords of :mod:`insitu.vision.detect`.
:func:`gray_centroid` (Li et al. §2.3, Eq. 7) is here; :func:`~insitu.vision.steger.gaussian_peak`
and :func:`~insitu.vision.steger.steger` in :mod:`insitu.vision.steger`; :func:`line_centres`
dispatches on the table and handles lines that run along the columns.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from insitu.vision.detect import (LineCentres, as_image, detect, gather, raw_saturated,
                                  saturation_level)
from insitu.vision.steger import gaussian_peak, steger


def gray_centroid(image: np.ndarray, k: float = 0.5, min_peak: float = 40.0,
                  window: int | None = 12, median: int = 3, *, band=None,
                  min_contrast: float = 20.0, snr: float = 6.0, continuity: bool = True,
                  saturation: float | None = None, subtract: bool = False) -> LineCentres:
    """Li et al.'s gray-centroid centres (§2.3, Eq. 7) of a line running along the rows.

    image: (H, W) uint8/uint16/float32. k: threshold scale, K = k · g_max (0 < k < 1).
    min_peak: absolute floor of the filtered peak. window: only pixels within ±window rows of
    the peak (None: the whole column as the paper, so a ghost above K counts too). median:
    aperture of the median pre-filter (0 or 1: none). Keywords: :mod:`insitu.vision.detect`.
    width: px above K.
    subtract: weights g_i − K instead of Eq. 7's g_i (not the paper; removes most of Eq. 7's
    phase-dependent bias of ≈ 0.15 px at k = 0.3, which comes from pixels entering the sum
    with weight K as the line moves).
    """
    img = as_image(image)
    det = detect(img, median, band, window, min_peak, min_contrast, snr, continuity)
    c, r, gmax = det.cols, det.row, det.gmax
    K = (k * gmax).astype(np.float32)
    if window is None:                                             # whole columns, (n, H)
        g = cv2.transpose(det.pre)[c].astype(np.float32)
        g[g <= K[:, None]] = 0
        width = (g > 0).sum(axis=1).astype(np.float64)
        if subtract:
            g = np.where(g > 0, g - K[:, None], 0)
        total = g.sum(axis=1, dtype=np.float64)
        v = (g @ np.arange(img.shape[0], dtype=np.float32)) / np.where(total > 0, total, 1)
    else:
        rows = np.arange(-window, window + 1)[:, None]
        g, inside = gather(det.pre, r[None, :] + rows, c)
        g[(g <= K) | ~inside] = 0
        width = (g > 0).sum(axis=0).astype(np.float64)
        if subtract:
            g = np.where(g > 0, g - K, 0)
        total = g.sum(axis=0, dtype=np.float64)
        v = r + (g * rows).sum(axis=0, dtype=np.float64) / np.where(total > 0, total, 1)
    return LineCentres(c.astype(np.float64), v.astype(np.float64), gmax.astype(np.float64),
                       width, det.contrast.astype(np.float64),
                       raw_saturated(img, det, saturation_level(img, saturation)), det.ambiguous)


def line_direction(image: np.ndarray) -> str:
    """"rows" if the line runs mostly along the rows (crosses more columns than rows), else
    "cols": counts of columns and rows whose maximum is above half-way between the frame's
    median and its maximum (max projections, ≈ 0.3 ms a 5 MPix frame)."""
    img = as_image(image)
    cmax, rmax = img.max(axis=0), img.max(axis=1)
    thr = (float(np.median(img[::16, ::16])) + float(cmax.max())) / 2
    return "cols" if (rmax > thr).sum() > (cmax > thr).sum() else "rows"


@dataclass(frozen=True)
class CentreMethod:
    """A centre method: ``find(image, band=…, **kw)`` → :class:`LineCentres` of a line running
    along the rows of ``image`` (H, W); ``options``: the fields of
    :class:`~insitu.vision.extract.CentreSettings` it takes; ``description``: one line."""

    find: Callable[..., LineCentres]
    options: tuple[str, ...]
    description: str


CENTRE_METHODS: dict[str, CentreMethod] = {
    "gray": CentreMethod(gray_centroid, ("k", "subtract"),
                         "gray centroid above k × the peak (Li et al. Eq. 7)"),
    "gaussian": CentreMethod(gaussian_peak, (), "3-point Gaussian peak fit per column"),
    "steger": CentreMethod(steger, (), "Steger's Hessian ridge detector (ours, the default)"),
}


def line_centres(image: np.ndarray, method: str = "gray", direction: str | None = None,
                 band=None, **kw) -> LineCentres:
    """Centres by ``method`` (a key of :data:`CENTRE_METHODS`) in image coordinates.

    direction: "rows" (one point per column), "cols" (one per row: the frame is transposed
    and u, v swapped back) or None (auto, :func:`line_direction`). band: (lo, hi) allowed
    range of the cross coordinate per scan line (v per column, or u per row for "cols").
    kw: passed to the method.
    """
    fn = CENTRE_METHODS[method].find
    img = as_image(image)
    direction = direction or line_direction(img)
    if direction == "rows":
        return fn(img, band=band, **kw)
    if direction != "cols":
        raise ValueError(f"direction must be 'rows', 'cols' or None, not {direction!r}")
    t = fn(cv2.transpose(img), band=band, **kw)
    return LineCentres(t.v, t.u, t.peak, t.width, t.contrast, t.saturated, t.ambiguous)
