"""Image files read safely: the header (Pillow's lazy open: PNG IHDR, JPEG SOF, TIFF IFD, BMP,
WebP, ...) gives the size before any pixel is decoded, so a 20000 x 20000 PNG of a few kB is
refused at once; a PNG's chunks must lie within the file and match their CRCs (a damaged length
makes OpenCV allocate and read for seconds, a damaged chunk makes libpng print); then OpenCV
decodes it and the decoded size must be the header's.
"""

from __future__ import annotations

import struct
import warnings
import zlib
from pathlib import Path

import cv2
import numpy as np

from insitu.errors import FormatError
from insitu.formats.limits import MAX_IMAGE_BYTES, MAX_IMAGE_PIXELS, check_file, read_limited


def image_size(path: str | Path, *, max_pixels: int = MAX_IMAGE_PIXELS,
               error: type[Exception] = FormatError) -> tuple[int, int]:
    """(width, height) px from the header of the image file ``path``; ``error`` naming it when
    it is not a regular file, too large in bytes, not an image Pillow knows, or larger than
    ``max_pixels``."""
    from PIL import Image

    check_file(path, MAX_IMAGE_BYTES, "image", missing="no such image file", error=error)
    Image.MAX_IMAGE_PIXELS = None       # Pillow decodes nothing here; max_pixels is checked below
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(path) as im:
                w, h = im.size
    except Exception as e:  # noqa: BLE001 — any header fault is one line naming the file
        raise error(f"{path}: not a readable image ({' '.join(str(e).split())[:80]})") from None
    if w <= 0 or h <= 0:
        raise error(f"{path}: image header gives {w}x{h} pixels")
    if w * h > max_pixels:
        raise error(f"{path}: image is {w}x{h} pixels, more than the {max_pixels / 1e6:g} Mpx "
                    "limit (refused from its header, before decoding)")
    return w, h


def read_image(path: str | Path, flags: int = cv2.IMREAD_UNCHANGED, *,
               max_pixels: int = MAX_IMAGE_PIXELS, expect: tuple[int, int] | None = None,
               expected: str = "expected", error: type[Exception] = FormatError) -> np.ndarray:
    """The decoded image (H, W) or (H, W, C), OpenCV's channel order and depth for ``flags``.
    The header is checked first (:func:`image_size`), and against ``expect`` = (width,
    height) when given (``expected``: how the message names it), so a frame of the wrong size
    is refused before it is decoded."""
    w, h = image_size(path, max_pixels=max_pixels if expect is None else 1 << 62, error=error)
    if expect is not None and expect[0] * expect[1] > max_pixels:
        raise error(f"{path}: {expected} {expect[0]}x{expect[1]}: more than the "
                    f"{max_pixels / 1e6:g} Mpx limit")
    if expect is not None and (w, h) != tuple(expect):
        raise error(f"{path}: image is {w}x{h} pixels, {expected} {expect[0]}x{expect[1]} "
                    "(width x height)")
    raw = read_limited(path, MAX_IMAGE_BYTES, "image", error=error)
    if raw.startswith(_PNG):
        _check_png(path, raw, error)
    data = np.frombuffer(raw, np.uint8)
    try:
        img = cv2.imdecode(data, flags) if data.size else None
    except cv2.error:
        img = None
    if img is None or img.size == 0:
        raise error(f"{path}: not a readable image (OpenCV cannot decode it)")
    if img.shape[:2] not in ((h, w), (w, h)):              # (w, h): EXIF-rotated by OpenCV
        raise error(f"{path}: decoded {img.shape[1]}x{img.shape[0]} pixels, but its header "
                    f"says {w}x{h}")
    return img


_PNG = b"\x89PNG\r\n\x1a\n"


def _check_png(path, raw: bytes, error: type[Exception]) -> None:
    """``error`` unless every chunk of the PNG ``raw`` lies within it, has the CRC it says, and
    the last is IEND."""
    i = len(_PNG)
    while i + 12 <= len(raw):
        n, kind = struct.unpack(">I4s", raw[i:i + 8])
        if n > len(raw) - i - 12:
            raise error(f"{path}: truncated or damaged PNG (chunk {kind!r} at byte {i} "
                        f"claims {n} bytes, only {len(raw) - i - 12} are left)")
        if zlib.crc32(raw[i + 4:i + 8 + n]) != struct.unpack(">I", raw[i + 8 + n:i + 12 + n])[0]:
            raise error(f"{path}: damaged PNG (chunk {kind!r} at byte {i}: CRC mismatch)")
        if kind == b"IEND":
            return
        i += 12 + n
    raise error(f"{path}: truncated PNG (no IEND chunk)")


PIXEL_BITS = (8, 10, 12, 14, 16)
"""Significant bits a frame's pixels may have (formats.md ``pixel_bits``)."""


def check_bits(where: str, img: np.ndarray, bits: int | None) -> None:
    """FormatError unless ``img`` fits ``bits`` significant bits (formats.md ``pixel_bits``:
    values 0 … 2^bits − 1; an 8-bit image holds 8): ``where`` names the file."""
    if bits is None:
        return
    if bits not in PIXEL_BITS:
        raise FormatError(f"{where}: pixel_bits: expected one of "
                          f"{', '.join(map(str, PIXEL_BITS))}, got {bits!r}")
    top = 2 ** bits - 1
    if (img.dtype == np.uint8) != (bits == 8) or (top < 65535 and int(img.max()) > top):
        raise FormatError(f"{where}: a {img.dtype} image holding up to {int(img.max())}, but "
                          f"pixel_bits is {bits} (values 0 … {top})")


def grey_image(path, img: np.ndarray) -> np.ndarray:
    """``img`` read from ``path`` as (H, W) uint8 or uint16: one channel, or three equal
    ones; FormatError naming the file for a colour image or another depth."""
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    elif img.ndim == 3 and img.shape[2] == 3:
        if not (np.array_equal(img[..., 0], img[..., 1])
                and np.array_equal(img[..., 0], img[..., 2])):
            raise FormatError(f"{path}: expected a single-channel (grey) image, got a colour "
                              "image with 3 channels that differ")
        img = np.ascontiguousarray(img[..., 0])
    elif img.ndim != 2:
        raise FormatError(f"{path}: expected a single-channel (grey) image, "
                          f"got {img.shape[2]} channels")
    if img.dtype not in (np.uint8, np.uint16):
        raise FormatError(f"{path}: expected an 8- or 16-bit image, got {img.dtype}")
    return img
