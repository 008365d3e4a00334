"""Raster sources: images (PNG, JPEG, BMP, ...) → :class:`Pattern`, and pixel masks → regions.

Image row 0 is the top; the pattern's y is up, so rows are flipped. Dark pixels are marked
(``invert=True`` marks the light ones). Pixel size comes from ``width_mm``, else ``dpi``, else
the file's own resolution (PNG pHYs, JPEG JFIF, BMP header), else 96 dpi.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.formats.images import read_image
from insitu.patterns.model import Pattern, contours_of

DEFAULT_DPI = 96.0
MODES = ("fill", "threshold", "dither")

_BAYER8 = np.array([[0, 32, 8, 40, 2, 34, 10, 42], [48, 16, 56, 24, 50, 18, 58, 26],
                    [12, 44, 4, 36, 14, 46, 6, 38], [60, 28, 52, 20, 62, 30, 54, 22],
                    [3, 35, 11, 43, 1, 33, 9, 41], [51, 19, 59, 27, 49, 17, 57, 25],
                    [15, 47, 7, 39, 13, 45, 5, 37], [63, 31, 55, 23, 61, 29, 53, 21]])


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Horizontal runs of True in a (H, W) mask: (row, first col, end col exclusive), each (R,)
    int, sorted by row then column."""
    m = np.asarray(mask, bool)
    pad = np.zeros((m.shape[0], m.shape[1] + 2), np.int8)
    pad[:, 1:-1] = m
    d = np.diff(pad, axis=1)
    r0, c0 = np.nonzero(d == 1)
    _, c1 = np.nonzero(d == -1)
    return r0, c0, c1


def mask_region(mask: np.ndarray, pixel_mm: float):
    """The union of the True cells of a (H, W) mask as shapely geometry in mm, y up: cell
    (row r, col c) covers x ∈ [c, c+1]·pixel_mm, y ∈ [H−r−1, H−r]·pixel_mm. Corners exact."""
    h = np.asarray(mask).shape[0]
    r, c0, c1 = runs(mask)
    if not len(r):
        return shapely.Polygon()
    # merge identical runs on consecutive rows into one rectangle
    o = np.lexsort((r, c1, c0))
    r, c0, c1 = r[o], c0[o], c1[o]
    new = np.ones(len(r), bool)
    new[1:] = (c0[1:] != c0[:-1]) | (c1[1:] != c1[:-1]) | (r[1:] != r[:-1] + 1)
    first = np.flatnonzero(new)
    last = np.append(first[1:], len(r)) - 1
    boxes = shapely.box(c0[first] * pixel_mm, (h - r[last] - 1) * pixel_mm,
                        c1[first] * pixel_mm, (h - r[first]) * pixel_mm)
    g = shapely.unary_union(boxes)
    return shapely.simplify(g, 0.0)


def scan_lines(mask: np.ndarray, pixel_mm: float) -> list[np.ndarray]:
    """One open path (2, 2) mm per run of True cells, along the row's centre line from the
    run's left edge to its right edge; rows alternate direction (bottom row first)."""
    h = np.asarray(mask).shape[0]
    r, c0, c1 = runs(mask)
    y = (h - r - 0.5) * pixel_mm
    out = []
    for i in np.lexsort((c0, -r)):
        seg = np.array([[c0[i] * pixel_mm, y[i]], [c1[i] * pixel_mm, y[i]]])
        out.append(seg if (h - r[i]) % 2 else seg[::-1])
    return out


def file_dpi(path: Path) -> float | None:
    """Resolution recorded in a PNG (pHYs), JPEG (JFIF) or BMP header, dots per inch."""
    try:
        with open(path, "rb") as f:
            head = f.read(1 << 16)
    except OSError:
        return None
    try:
        if head.startswith(b"\x89PNG\r\n\x1a\n"):
            i = 8
            while i + 8 <= len(head):
                n, kind = struct.unpack(">I4s", head[i:i + 8])
                if kind == b"pHYs" and n == 9:
                    ppx, _, unit = struct.unpack(">IIB", head[i + 8:i + 17])
                    return ppx * 0.0254 if unit == 1 and ppx > 0 else None
                if kind == b"IDAT":
                    return None
                i += 12 + n
        elif head[:2] == b"\xff\xd8" and head[6:11] == b"JFIF\x00":
            unit, dx = head[13], struct.unpack(">H", head[14:16])[0]
            return float(dx) if unit == 1 and dx > 1 else dx * 2.54 if unit == 2 and dx else None
        elif head[:2] == b"BM":
            ppm = struct.unpack("<i", head[38:42])[0]
            return ppm * 0.0254 if ppm > 0 else None
    except struct.error:
        return None
    return None


def image_gray(path: Path) -> np.ndarray:
    """(H, W) float64 in [0, 1] (0 black), alpha composited over white."""
    img = read_image(path)             # header first: size and pixel limits before decoding
    scale = 65535.0 if img.dtype == np.uint16 else 255.0 if img.dtype == np.uint8 else 1.0
    img = img.astype(np.float64) / scale
    if img.ndim == 2:
        return np.clip(img, 0, 1)
    alpha = img[:, :, 3] if img.shape[2] == 4 else 1.0
    b, g, r = img[:, :, 0], img[:, :, 1], img[:, :, 2]
    gray = 0.299 * r + 0.587 * g + 0.114 * b
    return np.clip(gray * alpha + (1.0 - alpha), 0, 1)


def raster_pattern(gray: np.ndarray, pixel_mm: float, mode: str = "fill",
                   threshold: float = 0.5, invert: bool = False, name: str = "") -> Pattern:
    """(H, W) gray image in [0, 1] → Pattern with the image's rectangle as its frame.

    mode "fill": pixels darker than ``threshold`` become filled contours (exact pixel edges),
    hatched later at any spacing; "threshold": the same pixels as scan lines, one per pixel row;
    "dither": gray levels as ordered (Bayer 8×8) dots, as scan lines.
    """
    if mode not in MODES:
        raise FormatError(f"{name}: image mode must be one of {', '.join(MODES)}, got {mode!r}")
    g = 1.0 - gray if invert else gray
    if mode == "dither":
        h, w = g.shape
        t = (_BAYER8[np.arange(h)[:, None] % 8, np.arange(w)[None, :] % 8] + 0.5) / 64.0
        mask = g < t
    else:
        mask = g < threshold
    h, w = mask.shape
    frame = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float64) * pixel_mm
    if mode == "fill":
        return Pattern(tuple(contours_of(mask_region(mask, pixel_mm))), (), name, frame)
    return Pattern((), tuple(scan_lines(mask, pixel_mm)), name, frame)


def load_image(path: str | Path, dpi: float | None = None, width_mm: float | None = None,
               mode: str = "fill", threshold: float = 0.5, invert: bool = False) -> Pattern:
    """Image file → Pattern (see :func:`raster_pattern`); ``width_mm`` wins over ``dpi``."""
    path = Path(path)
    gray = image_gray(path)
    if width_mm is not None:
        if not width_mm > 0:
            raise FormatError(f"{path}: width must be > 0 mm, got {width_mm}")
        pixel = width_mm / gray.shape[1]
    else:
        d = dpi if dpi is not None else file_dpi(path) or DEFAULT_DPI
        if not d > 0:
            raise FormatError(f"{path}: dpi must be > 0, got {d}")
        pixel = 25.4 / d
    p = raster_pattern(gray, pixel, mode, threshold, invert, path.name)
    if p.is_empty:
        raise FormatError(f"{path}: no dark pixels to mark (empty pattern; threshold "
                          f"{threshold}{', inverted' if invert else ''})")
    return p
