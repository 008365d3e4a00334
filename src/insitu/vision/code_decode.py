"""Decode codes in a grey picture with zxing-cpp, trying harder than one call: the picture as it
is (what a plain zxing-cpp call sees), stretched between its 1st and 99th percentiles under
zxing's local and global thresholds, then binarised (Otsu) with the marks thinned by 1 px up to
a third of a module — a laser or peened mark grows beyond its modules, leaving the light ones
small — and, for a symbol of few pixels a module, all of this again on the picture enlarged
twice (bicubic) after a local contrast equalisation (CLAHE), which lifts a faint mark on a
shaded or curved part (pictures up to :data:`ENLARGE_MAX_PX` a side). Before enlarging, the
same again sharpened (:func:`sharpened`): a lens's blur leaves a grown mark's small light
modules grey. Dark marks on light ground or light on dark (``try_invert``).
"""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import numpy as np

MATRIX_FORMATS = ("QRCode", "MicroQRCode", "DataMatrix")   # zxing-cpp's names, 2-D matrix codes
ENLARGE_MAX_PX = 2048      # pictures larger than this (either side) are not enlarged
SHARPEN = 1.0
"""Unsharp masking's amount, its blur σ a sixth of a module (:func:`sharpened`)."""


def stretch_u8(picture: np.ndarray) -> np.ndarray:
    """(H, W) uint8 stretched between the 1st and 99th percentiles of the seen (finite)
    pixels; unseen ones the median. Colour (H, W, 3) BGR is turned grey first."""
    p = np.asarray(picture)
    if p.ndim == 3:
        p = cv2.cvtColor(p, cv2.COLOR_BGR2GRAY if p.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    p = p.astype(np.float32)
    seen = np.isfinite(p)
    lo, hi = np.percentile(p[seen], [1, 99])
    p = np.where(seen, p, np.median(p[seen]))
    return np.clip((p - lo) / max(hi - lo, 1e-6) * 255, 0, 255).astype(np.uint8)


def sharpened(img: np.ndarray, module_px: float) -> np.ndarray:
    """``img`` (H, W) uint8 unsharp-masked by :data:`SHARPEN` with a blur of a sixth of a
    module (``module_px`` px): the light modules a grown, blurred mark leaves grey brought
    back (a 0.3 mm Data Matrix on the simulated rig, 3.8 camera px a module, lens PSF σ
    0.67 px: not read without)."""
    f = img.astype(np.float32)
    f += SHARPEN * (f - cv2.GaussianBlur(f, (0, 0), max(module_px / 6, 0.5)))
    return np.clip(f, 0, 255).astype(np.uint8)


def _attempts(picture: np.ndarray, module_px: float) -> Iterator[tuple[np.ndarray, str]]:
    """The pictures (uint8) and zxing binarizer names of the ladder, cheapest first."""
    raw = np.asarray(picture)
    if raw.dtype == np.uint8:
        yield (cv2.cvtColor(raw, cv2.COLOR_BGR2GRAY) if raw.ndim == 3 else raw), "LocalAverage"
    img = stretch_u8(picture)
    yield from _thresholds(img, module_px)
    yield from _thresholds(sharpened(img, module_px), module_px)
    if max(img.shape) <= ENLARGE_MAX_PX:
        img = cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(img)
        yield from _thresholds(cv2.resize(img, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC),
                               2 * module_px)


def _thresholds(img: np.ndarray, module_px: float) -> Iterator[tuple[np.ndarray, str]]:
    """``img`` under zxing's local and global thresholds, then binarised (Otsu) with the dark
    and the light marks thinned by 1 px up to a third of a module (``module_px`` px)."""
    yield img, "LocalAverage"
    yield img, "GlobalHistogram"
    _, bw = cv2.threshold(img, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    for k in range(1, max(2, int(module_px / 3)) + 1):
        kernel = np.ones((2 * k + 1, 2 * k + 1), np.uint8)
        yield cv2.dilate(bw, kernel), "BoolCast"            # dark marks thinned
        yield cv2.erode(bw, kernel), "BoolCast"             # light marks thinned


def read_codes(picture: np.ndarray, formats: str | tuple[str, ...] = MATRIX_FORMATS,
               module_px: float = 8.0, enlarge: bool = True) -> tuple[list, float]:
    """The codes zxing-cpp reads in ``picture`` ((H, W) grey of any depth, NaN: not seen, or
    (H, W, 3) BGR) of ``formats`` (zxing-cpp's format names) at the first rung of the ladder
    that reads any, and that rung's scale (1 or 2: positions are in its pixels). ``module_px``:
    a module's size in pixels, as far as known; ``enlarge``: also try the enlarged rung (never
    for a picture larger than :data:`ENLARGE_MAX_PX`: its modules are not few pixels, and
    four times its pixels would cost seconds and memory).
    ([], 1.0) when nothing is read."""
    import zxingcpp

    names = (formats,) if isinstance(formats, str) else formats
    fmt = [getattr(zxingcpp.BarcodeFormat, name) for name in names]
    if not np.isfinite(np.asarray(picture, np.float32)).any():
        return [], 1.0
    small = np.asarray(picture).shape[0]
    for img, binarizer in _attempts(picture, module_px):
        scale = img.shape[0] / small
        if scale > 1 and not enlarge:
            break
        found = zxingcpp.read_barcodes(img, formats=fmt, try_rotate=True, try_downscale=True,
                                       try_invert=True,
                                       binarizer=getattr(zxingcpp.Binarizer, binarizer))
        if found:
            return list(found), float(scale)
    return [], 1.0
