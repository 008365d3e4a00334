"""Sub-pixel centres of a laser line: one crossing per scan column (rows mode) or per row, by
one of the methods of :data:`CENTRE_METHODS`.

Every method uses the detection stage and keywords of :mod:`insitu.vision.detect`.
:func:`gray_centroid` (Li et al. §2.3, Eq. 7) is here; :func:`~insitu.vision.steger.gaussian_peak`
and :func:`~insitu.vision.steger.steger` in :mod:`insitu.vision.steger`; :func:`line_centres`
dispatches on the table, picks the laser's channel of a colour image (:func:`as_gray`) and
handles lines that run along the columns, found from the image's structure when not given
(:func:`line_direction`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np

from insitu.errors import MeasurementError
from insitu.vision.detect import (LineCentres, as_image, band_background, detect, gather,
                                  raw_saturated, saturation_level)
from insitu.vision.steger import gaussian_peak, steger


def gray_centroid(image: np.ndarray, k: float = 0.5, min_peak: float = 40.0,
                  window: int | None = 12, median: int = 3, *, band=None,
                  min_contrast: float = 20.0, snr: float = 6.0, continuity: bool = True,
                  saturation: float | None = None, subtract: bool = False,
                  background: bool = False, extend_ends: bool = True,
                  upper: int = 0) -> LineCentres:
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
    background: K = bg + k · (g_max − bg) with bg the column's local background, running
    linearly between the ends of the ±window band (window None: the detection's ``bg``),
    weights g_i − K (``subtract`` implied): a bright or sloping surface under the line no
    longer enters the sum. False: Eq. 7, the paper mode that
    :data:`~insitu.vision.extract.PAPER_SETTINGS` reproduces.
    """
    img = as_image(image)
    det = detect(img, median, band, window, min_peak, min_contrast, snr, continuity,
                 extend_ends=extend_ends, upper=upper)
    c, r, gmax = det.cols, det.row, det.gmax
    if background and window is not None:
        return _above_background(img, det, k, window, saturation)
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


def _above_background(img, det, k, window, saturation) -> LineCentres:
    """Gray centroid above the local background of each column (see gray_centroid): the
    background runs linearly between the medians of the 3 px at each end of the ±window band,
    K = k · (g_max − that background at the peak); weights g − background − K."""
    c, r, gmax = det.cols, det.row, det.gmax
    rows = np.arange(-window, window + 1)[:, None]
    g, inside = gather(det.pre, r[None, :] + rows, c)
    bg = band_background(g)
    g -= bg + k * (gmax - bg[window])
    g[(g <= 0) | ~inside] = 0
    total = g.sum(axis=0, dtype=np.float64)
    v = r + (g * rows).sum(axis=0, dtype=np.float64) / np.where(total > 0, total, 1)
    return LineCentres(c.astype(np.float64), v, gmax.astype(np.float64),
                       (g > 0).sum(axis=0).astype(np.float64), det.contrast.astype(np.float64),
                       raw_saturated(img, det, saturation_level(img, saturation)),
                       det.ambiguous)


class ImageInputError(MeasurementError, ValueError):
    """An image, channel or direction the centres cannot use (one line naming it)."""


CHANNELS = {"b": 0, "g": 1, "r": 2}                  # BGR, as OpenCV reads colour images
_SIDE = 640         # the structure of the line is judged on the frame shrunk to ≤ this, px
_HAT = 7            # top-hat structuring element, px of the shrunk frame (> the line's width)


def _shrink(img: np.ndarray) -> np.ndarray:
    """``img`` (H, W[, C]) shrunk by the integer factor (area mean, float32) that brings its
    longer side to ≤ _SIDE px: a thin line stays a (weaker) ridge."""
    f = max(1, -(-max(img.shape[:2]) // _SIDE))
    if f > 1 and min(img.shape[:2]) >= f:
        img = cv2.resize(img, (img.shape[1] // f, img.shape[0] // f),
                         interpolation=cv2.INTER_AREA)
    return img.astype(np.float32)


def _ridges(small: np.ndarray) -> np.ndarray:
    """White top-hat (H, W) float32 of a shrunk frame: thin bright lines stay, areas wider
    than _HAT px (a white board, lit background) and their edges go."""
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (_HAT, _HAT))
    return cv2.morphologyEx(small, cv2.MORPH_TOPHAT, kernel, borderType=cv2.BORDER_REPLICATE)


def _line_contrast(hat: np.ndarray) -> float:
    """How strongly a line stands out of a top-hat image (H, W): the mean over the scan lines
    (rows or columns, whichever the line crosses more strongly) of their top-hat maximum."""
    return float(max(hat.max(axis=0).mean(), hat.max(axis=1).mean()))


def as_gray(image, channel: str = "auto") -> np.ndarray:
    """The (H, W) image the centres are found in: ``image`` itself if gray, else one channel of
    an (H, W, 3) BGR (or (H, W, 1)) image. channel: "r", "g", "b", or "auto": the channel
    whose line stands out most over its own background (mean top-hat maximum per scan line).
    ImageInputError (one line) for any other shape or channel name."""
    img = np.asarray(image)
    if channel != "auto" and channel not in CHANNELS:
        raise ImageInputError(f"channel {channel!r}: expected auto, r, g or b")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    elif img.ndim == 3 and img.shape[2] == 3 and img.size:
        if channel == "auto":
            small = _shrink(img)
            channel = "bgr"[int(np.argmax([_line_contrast(_ridges(
                np.ascontiguousarray(small[:, :, c]))) for c in range(3)]))]
        img = cv2.extractChannel(np.ascontiguousarray(img), CHANNELS[channel])
    if img.ndim != 2 or img.size == 0:
        raise ImageInputError(f"image of shape {img.shape}: expected a non-empty gray (H, W) "
                              "or colour (H, W, 3) image")
    return as_image(img)


def line_direction(image: np.ndarray) -> str:
    """"rows" if the line runs mostly along the rows (crosses more columns than rows), else
    "cols", from the image's structure: the orientation of the gradient energy (structure
    tensor) of the white top-hat of the shrunk frame (:func:`_ridges`), where a bright board or
    background has gone and only thin ridges stay. A line along the rows has its gradients
    across them (along y). ≈ 2 ms a 5 MPix uint8 frame (benchmarks/centres_speed.py)."""
    hat = _ridges(_shrink(as_image(image)))
    if min(hat.shape) < 3:
        return "rows" if hat.shape[1] >= hat.shape[0] else "cols"
    gx = cv2.Sobel(hat, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(hat, cv2.CV_32F, 0, 1, ksize=3)
    return "cols" if float(np.vdot(gx, gx)) > float(np.vdot(gy, gy)) else "rows"


@dataclass(frozen=True)
class CentreMethod:
    """A centre method: ``find(image, band=…, **kw)`` → :class:`LineCentres` of a line running
    along the rows of ``image`` (H, W); ``options``: the fields of
    :class:`~insitu.vision.extract.CentreSettings` it takes; ``description``: one line;
    ``defaults``: its keywords for images of unknown origin (``insitu centres``), the best
    measured on real photographs (benchmarks/real_lines.py)."""

    find: Callable[..., LineCentres]
    options: tuple[str, ...]
    description: str
    defaults: Mapping[str, object] = field(default_factory=dict)


CENTRE_METHODS: dict[str, CentreMethod] = {
    "gray": CentreMethod(gray_centroid, ("k", "subtract", "background", "extend_ends"),
                         "gray centroid above k × the peak (Li et al. Eq. 7), or above the "
                         "background (background=True)", {"k": 0.5, "background": True}),
    "gaussian": CentreMethod(gaussian_peak, ("extend_ends",),
                             "3-point Gaussian peak fit per column"),
    "steger": CentreMethod(steger, ("extend_ends",),
                           "Steger's Hessian ridge detector (ours, the default)"),
}


def line_centres(image: np.ndarray, method: str = "gray", direction: str | None = None,
                 band=None, channel: str = "auto", **kw) -> LineCentres:
    """Centres by ``method`` (a key of :data:`CENTRE_METHODS`) in image coordinates.

    image: (H, W) gray or (H, W, 3) BGR (``channel``: :func:`as_gray`). direction: "rows" (one
    point per column), "cols" (one per row: the frame is transposed and u, v swapped back) or
    None (auto, :func:`line_direction`). band: (lo, hi) allowed range of the cross coordinate
    per scan line (v per column, or u per row for "cols"). kw: passed to the method.
    ImageInputError for another method, direction, channel or image shape.
    """
    if method not in CENTRE_METHODS:
        raise ImageInputError(f"centre method {method!r}: expected one of "
                              f"{', '.join(CENTRE_METHODS)}")
    if direction not in (None, "rows", "cols"):
        raise ImageInputError(f"direction {direction!r}: expected rows, cols or auto")
    fn = CENTRE_METHODS[method].find
    img = as_gray(image, channel)
    direction = direction or line_direction(img)
    if direction == "rows":
        return fn(img, band=band, **kw)
    t = fn(cv2.transpose(img), band=band, **kw)
    return LineCentres(t.v, t.u, t.peak, t.width, t.contrast, t.saturated, t.ambiguous)
