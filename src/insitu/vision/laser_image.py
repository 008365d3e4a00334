"""The image a laser line's centres are found in, from a camera frame or anyone's photograph:
its full scale, the laser's channel of a colour image, and a laser-off frame taken away.

* Full scale: 2^pixel_bits − 1 (a Mono12 camera's frames hold 0 … 4095 in 16 bits); without
  pixel_bits, the dtype's (255, 65535; float frames: the 8-bit scale, 255). Every threshold
  of the detection is a fraction of it (:mod:`insitu.vision.detect`).
* Colour: the laser's channel c, and where the light is the laser's colour: the excess
  X = I_c − (I_a + I_b) / 2 of c over the two others (for a red line, R against G and B; the
  mean, not the larger, because a camera's blue pixels see a green laser too), and of X its
  thin ridges (white top-hat, 2·reach + 1 px: a red door or an orange wall is no stripe). A
  stripe's clipped core is white (X = 0) but its halo is not, so a pixel may hold the line
  when it is on a ridge of laser-coloured light or has one within reach on both sides
  (``allow``; a ridge: at least :data:`CHROMA` of full scale and :data:`CHROMA_SNR` times the
  excess's own noise); white room light, lamps, furniture and their edges hold none. ``channel="auto"`` takes the
  channel whose excess forms the strongest thin ridges; those ridges (``ridge``) also tell
  which way the line runs.
* Laser-off frame: subtracted, channel by channel; a pixel the laser clipped (clipped in the
  frame, not in the laser-off frame) stays at full scale (the core of the stripe), so the
  clipped plateau is still found as one; one clipped in both is the scene's, and goes.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.errors import MeasurementError
from insitu.formats.images import PIXEL_BITS
from insitu.vision.noise_kernel import read_bounds

CHANNELS = {"b": 0, "g": 1, "r": 2}                  # BGR, as OpenCV reads colour images
CHROMA = 12 / 255
"""Least excess of the laser's channel over the others that counts as laser-coloured, of full
scale."""
CHROMA_SNR = 6.0
"""… and least multiple of the excess's noise sigma."""
WHITE = 0.85
"""Least value of all three channels, of full scale, of a pixel counted white: a stripe's
clipped core (a JPEG smears its chroma a few tens of gray values below full scale)."""
EDGES = 0.02
"""The fraction of a frame's pixels, of the strongest gradient, whose colour fringes
:func:`colour_margin` weighs the line's colour against."""
LIT = 0.15
"""Least thin ridge of the laser's channel itself, of full scale, that is the laser's light
(a reflection of the stripe, a glint, the stripe on furniture), not a colour fringe: a
fringe is a step in that channel (:func:`colour_margin`)."""
_SIDE = 640         # the structure of the line is judged on the frame shrunk to ≤ this, px
_HAT = 7            # top-hat structuring element, px of the shrunk frame (> the line's width)


class ImageInputError(MeasurementError, ValueError):
    """An image, channel or direction the centres cannot use (one line naming it)."""


@dataclass(frozen=True)
class LaserImage:
    """gray: (H, W) uint8/uint16/float32, the laser's light (its channel, laser-off frame
    taken away). allow: (H, W) bool, where a peak may be taken (module docstring; None:
    everywhere, gray input). full_scale: the frame's full scale in gray's units. channel:
    "r", "g", "b" or None (gray input). ridge: float32, the thin ridges of the laser's excess
    over the other channels, at a smaller scale for a large frame (None: gray input).
    total: (H, W) the sum of the three channels (full scale 3 · full_scale), where a core
    clipped white stands out over a halo that clips the laser's channel (None: gray input,
    or a channel given). bgr: the colour frame (H, W, 3) its :func:`excess` is made of (None:
    gray input, a channel given, or a laser-off frame taken away). halo: as ridge, on a
    top-hat 3 × wider, that keeps a halo wider than the reach (None: gray input). chroma:
    (H, W) float32, the laser channel's excess over the mean of the two others in bgr (None
    with bgr)."""

    gray: np.ndarray
    allow: np.ndarray | None
    full_scale: float
    channel: str | None
    ridge: np.ndarray | None = None
    total: np.ndarray | None = None
    bgr: np.ndarray | None = None
    halo: np.ndarray | None = None
    chroma: np.ndarray | None = None


def full_scale(dtype: np.dtype, pixel_bits: int | None = None) -> float:
    """2^pixel_bits − 1, or the dtype's full scale (uint8 255, uint16 65535, float 255).
    ImageInputError for bits outside :data:`PIXEL_BITS` or more than the dtype holds."""
    dtype = np.dtype(dtype)
    if pixel_bits is None:
        return float(np.iinfo(dtype).max) if dtype.kind == "u" else 255.0
    if pixel_bits not in PIXEL_BITS or (dtype == np.uint8 and pixel_bits != 8):
        raise ImageInputError(f"pixel_bits {pixel_bits!r}: expected one of "
                              f"{', '.join(map(str, PIXEL_BITS))} (8 for an 8-bit image)")
    return float(2 ** pixel_bits - 1)


def check_bits(img: np.ndarray, pixel_bits: int | None) -> float:
    """The full scale of ``img``; ImageInputError when a pixel exceeds 2^pixel_bits − 1."""
    fs = full_scale(img.dtype, pixel_bits)
    if pixel_bits is not None and pixel_bits < 16 and img.dtype != np.uint8 and img.size:
        top = float(img.max())
        if top > fs:
            raise ImageInputError(f"pixel_bits {pixel_bits}: the image holds {top:g}, above "
                                  f"the {pixel_bits}-bit full scale {fs:g} (give its camera's "
                                  "bits, or none for the file's depth)")
    return fs


def shrink(img: np.ndarray) -> np.ndarray:
    """``img`` (H, W[, C]) shrunk by the integer factor (area mean, float32) that brings its
    longer side to ≤ _SIDE px: a thin line stays a (weaker) ridge."""
    f = max(1, -(-max(img.shape[:2]) // _SIDE))
    if f > 1 and min(img.shape[:2]) >= f:
        img = cv2.resize(img, (img.shape[1] // f, img.shape[0] // f),
                         interpolation=cv2.INTER_AREA)
    return img.astype(np.float32)


def ridges(small: np.ndarray) -> np.ndarray:
    """White top-hat (H, W) float32 of a shrunk frame: thin bright lines stay, areas wider
    than _HAT px (a white board, lit background) and their edges go."""
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (_HAT, _HAT))
    return cv2.morphologyEx(small, cv2.MORPH_TOPHAT, kernel, borderType=cv2.BORDER_REPLICATE)


def line_contrast(hat: np.ndarray) -> float:
    """How strongly a line stands out of a top-hat image (H, W): the mean over the scan lines
    (rows or columns, whichever the line crosses more strongly) of their top-hat maximum."""
    return float(max(hat.max(axis=0).mean(), hat.max(axis=1).mean()))


def _excess(bgr: np.ndarray, c: int, ch=None) -> np.ndarray:
    """(H, W) float32: channel c minus the mean of the two others (ch: bgr's channels, when
    split already)."""
    ch = cv2.split(bgr) if ch is None else ch
    a, b = (ch[k] for k in range(3) if k != c)
    return cv2.addWeighted(ch[c], 1.0, cv2.add(a, b, dtype=cv2.CV_32F), -0.5, 0.0,
                           dtype=cv2.CV_32F)


def read_window(img: np.ndarray, step: int = 32) -> np.ndarray:
    """The part of the frame ``img`` (H, W) its camera read: a frame read with a region of
    interest comes whole with 0 outside it (:class:`~insitu.devices.protocols.RoiCamera`), so
    the rectangle of the ``step`` px grid's points other than 0, its edges found to the pixel
    (:func:`~insitu.vision.noise_kernel.read_bounds`); the whole frame when every grid point
    holds a value (a region narrower than ``step`` px is not seen), and any other than an
    integer frame (a camera's)."""
    if img.dtype.kind != "u":
        return img
    r0, r1, c0, c1 = read_bounds(img, step)
    return img if (r0, r1, c0, c1) == (0, *img.shape[:1], 0, img.shape[1]) else img[r0:r1, c0:c1]


def noise_sigma(img: np.ndarray) -> float:
    """Robust noise sigma of (H, W) ``img`` from differences of rows 8 apart, ≤ 32 row
    pairs, every second column (a line or an edge moves few of them), over the part of the
    frame its camera read (:func:`read_window`)."""
    img = read_window(img)
    H = img.shape[0]
    d = min(8, H - 1)
    if d < 1:
        return 0.0
    idx = np.arange(0, H - d, max(1, (H - d) // 32))
    diff = img[idx, ::2].astype(np.float32) - img[idx + d, ::2].astype(np.float32)
    return float(1.4826 / np.sqrt(2.0) * np.median(np.abs(diff)))


def _auto_channel(bgr: np.ndarray) -> int:
    """The channel whose excess over the others forms the strongest thin ridges."""
    small = shrink(bgr)
    ch = cv2.split(small)
    return int(np.argmax([line_contrast(ridges(_excess(small, c, ch))) for c in range(3)]))


def colour_reach(shape) -> tuple[int, int]:
    """How far (px) laser colour is looked for beside a line in a frame of ``shape``: 1 % of
    its shorter side, ≥ 3; and the block size (px) its colour is pooled in (reach // 3)."""
    reach = max(3, round(min(shape[:2]) / 100))
    return reach, max(1, reach // 3)


def colour_margin(li: LaserImage, u: np.ndarray, v: np.ndarray) -> float:
    """How much more laser colour the line at centres ``u``, ``v`` (n,) px carries than the
    colour fringes at the frame's edges (a lens's chromatic aberration, JPEG chroma): the
    median over the centres of the ridges of the laser's excess (``li.halo``: a halo wider
    than the reach is the line's colour too) within reach, over their 99th percentile at the frame's strongest edges away from the line
    (and its halo: 4 reach on either side) and from the thin ridges of the laser's channel
    itself (:data:`LIT`: its reflections and glints are no fringes). The edges: the top
    :data:`EDGES` of the gradient of the scene, the sum of the two other channels (of the
    laser's channel when ``li.total`` is None): a fringe lies on an edge of the scene, a glint
    of the laser is none. Below 1 the colour cannot tell the line from the edges of a bright
    pattern. inf for a gray image or no centres."""
    if li.ridge is None or not len(u):
        return np.inf
    H, W = li.gray.shape
    reach, f = colour_reach((H, W))
    thin = li.ridge if li.halo is None else li.halo
    h, w = thin.shape
    r = 2 * (reach // f) + 1
    near_max = cv2.dilate(thin, np.ones((r, r), np.uint8))
    cu = np.clip((np.asarray(u) / f).astype(np.int64), 0, w - 1)
    cv_ = np.clip((np.asarray(v) / f).astype(np.int64), 0, h - 1)
    line = np.zeros((h, w), np.uint8)
    line[cv_, cu] = 1
    side = 2 * (r + 2 * (reach // f)) + 1                 # the line and its halo, ±4 reach
    line = cv2.dilate(line, np.ones((side, side), np.uint8)) > 0
    def small(img):
        return img if f == 1 else cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    gray = small(li.gray)
    scene = gray if li.total is None else \
        small(li.total).astype(np.float32) - gray.astype(np.float32)
    grad = cv2.magnitude(cv2.Sobel(scene, cv2.CV_32F, 1, 0), cv2.Sobel(scene, cv2.CV_32F, 0, 1))
    least = np.percentile(grad.ravel()[::4], 100 * (1 - EDGES))           # every 4th pixel
    lit = cv2.morphologyEx(gray, cv2.MORPH_TOPHAT, np.ones((r, r), np.uint8),
                           borderType=cv2.BORDER_REPLICATE) >= LIT * li.full_scale
    lit = cv2.dilate(lit.view(np.uint8), np.ones((r, r), np.uint8)) > 0
    edge = (grad >= least) & (grad > 0) & ~line & ~lit
    fringe = float(np.percentile(near_max[edge], 99)) if edge.any() else 0.0
    stripe = float(np.median(near_max[cv_, cu]))
    return stripe / max(fringe, CHROMA * li.full_scale)


def _laser_coloured(bgr: np.ndarray, c: int, fs: float, ch):
    """The thin ridges (white top-hat) of channel c's excess, (H, W) bool: where they
    (≥ :data:`CHROMA` · fs and :data:`CHROMA_SNR` · their noise) are, or lie within reach
    (1 % of the shorter side) on both sides — above and below, or left and right — of the
    pixel or of the white run it lies in (:func:`_flanked`; a run's flanks judged on a
    top-hat 3 × wider, as a halo can be wider than the reach): the halo round a core clipped
    white; a white thing beside a red one has them on one side only. Made on the excess
    max-pooled by reach // 3 (a thin ridge keeps its peak), with reach // 3 ≥ 3 px left: a
    full-HD frame in 3 × 3 blocks; and the excess's top-hat 3 × wider, on the same blocks;
    also the excess itself, (H, W) float32. ch: bgr's three channels (cv2.split)."""
    H, W = bgr.shape[:2]
    reach, f = colour_reach(bgr.shape)
    excess = chroma = _excess(bgr, c, ch)
    white = cv2.compare(cv2.min(cv2.min(ch[0], ch[1]), ch[2]), WHITE * fs, cv2.CMP_GE)
    h, w = H // f, W // f
    if f > 1:
        pool = np.ones((f, f), np.uint8)
        excess = cv2.dilate(excess, pool, anchor=(0, 0))[:h * f:f, :w * f:f]
        white = cv2.dilate(white, pool, anchor=(0, 0))[:h * f:f, :w * f:f]
    square = np.ones((2 * (reach // f) + 1,) * 2, np.uint8)
    thin = cv2.morphologyEx(excess, cv2.MORPH_TOPHAT, square, borderType=cv2.BORDER_REPLICATE)
    least = max(CHROMA * fs, CHROMA_SNR * noise_sigma(excess))
    laser, r = (thin >= least).astype(np.uint8), reach // f
    near = cv2.dilate(laser, np.ones((3, 3), np.uint8))
    for shape, ends in (((r + 1, 1), ((0, 0), (0, r))), ((1, r + 1), ((0, 0), (r, 0)))):
        a, b = (cv2.dilate(laser, np.ones(shape, np.uint8), anchor=e) for e in ends)
        near |= a & b
    wb = white > 0
    halo = cv2.morphologyEx(excess, cv2.MORPH_TOPHAT, np.ones((6 * r + 1,) * 2, np.uint8),
                            borderType=cv2.BORDER_REPLICATE)
    if wb.any():
        lb = halo >= least
        near |= (_flanked(lb, wb, r) | _flanked(lb.T.copy(), wb.T.copy(), r).T).view(np.uint8)
    if f > 1:
        near = cv2.resize(near, (w * f, h * f), interpolation=cv2.INTER_NEAREST)
        near = cv2.copyMakeBorder(near, 0, H - h * f, 0, W - w * f, cv2.BORDER_REPLICATE)
    return thin, near > 0, halo, chroma


def _flanked(laser: np.ndarray, white: np.ndarray, r: int) -> np.ndarray:
    """(n, m) bool: the runs of ``white`` along the rows (n, m) bool at most 4 r long with
    ``laser`` (n, m) bool from r + 1 px before their first pixel to their last, and from
    their first to r + 1 px after their last (a stripe's core clipped white, its halo beside
    it; a lamp or a window is wider). Worked out on the rows that hold white only."""
    out = np.zeros(laser.shape, bool)
    sel = np.flatnonzero(white.any(axis=1))
    if not len(sel):
        return out
    laser, white = laser[sel], white[sel]
    n, m = laser.shape
    pad = np.zeros((n, r + 2), bool)
    edge = np.diff(np.hstack([pad, white, pad]).view(np.int8), axis=1)
    rows, first = np.nonzero(edge == 1)
    first = first + 1                                          # in the padded frame's columns
    last = np.nonzero(edge == -1)[1]
    cum = np.zeros((n, m + 2 * r + 5), np.int32)
    np.cumsum(np.hstack([pad, laser, pad]), axis=1, out=cum[:, 1:])   # cum[:, j]: laser < j
    before = cum[rows, last + 1] - cum[rows, first - r - 1]      # r + 1 px before … its end
    after = cum[rows, last + r + 2] - cum[rows, first]           # its start … r + 1 px after
    ok = (before > 0) & (after > 0) & (last - first < 4 * r)
    mark = np.zeros((n, m + 2 * r + 5), np.int8)
    mark[rows[ok], first[ok]] = 1                  # runs are ≥ 1 px apart: no index twice
    mark[rows[ok], last[ok] + 1] = -1
    out[sel] = np.cumsum(mark, axis=1, dtype=np.int8)[:, r + 2:r + 2 + m] > 0
    return out


def laser_image(image, channel: str = "auto", laser_off=None,
                pixel_bits: int | None = None) -> LaserImage:
    """The :class:`LaserImage` of ``image``: (H, W) gray, or (H, W, 3) BGR / (H, W, 1).
    channel: "r", "g", "b" or "auto" (colour images). laser_off: the same camera's frame with
    the laser off (same shape), subtracted. pixel_bits: the camera's significant bits (None:
    the dtype's). ImageInputError (one line) for another shape, channel, a laser-off frame
    that does not match, or values beyond pixel_bits."""
    img = np.asarray(image)
    if channel != "auto" and channel not in CHANNELS:
        raise ImageInputError(f"channel {channel!r}: expected auto, r, g or b")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    colour = img.ndim == 3 and img.shape[2] == 3 and img.size > 0
    if not colour and (img.ndim != 2 or img.size == 0):
        raise ImageInputError(f"image of shape {img.shape}: expected a non-empty gray (H, W) "
                              "or colour (H, W, 3) image")
    if img.dtype not in (np.uint8, np.uint16, np.float32):
        img = img.astype(np.uint8 if img.dtype == bool else np.float32)
    fs = check_bits(img, pixel_bits)
    off = None
    if laser_off is not None:
        off = np.asarray(laser_off)
        if off.ndim == 3 and off.shape[2] == 1:
            off = off[:, :, 0]
        if off.shape != img.shape:
            raise ImageInputError(f"laser-off frame of shape {off.shape}: expected the "
                                  f"image's {img.shape}")
        on = img
        img = cv2.subtract(on, off.astype(on.dtype))
        img[(on >= fs) & (off < fs)] = fs               # the laser clipped it: the core
    if not colour:
        return LaserImage(np.ascontiguousarray(img), None, fs, None)
    img = np.ascontiguousarray(img)
    if channel != "auto":
        c = CHANNELS[channel]
    elif off is not None:               # the channel the laser added most light to
        c = int(np.argmax(cv2.sumElems(img)[:3]))
    else:
        c = _auto_channel(img)
    ch = cv2.split(img)
    thin, allow, halo, chroma = _laser_coloured(img, c, fs, ch)
    total = None
    if channel == "auto":
        depth = cv2.CV_16U if img.dtype == np.uint8 else cv2.CV_32F
        total = cv2.add(cv2.add(ch[0], ch[1], dtype=depth), ch[2], dtype=depth)
    keep = channel == "auto" and off is None
    return LaserImage(ch[c], allow, fs, "bgr"[c], thin, total, img if keep else None, halo,
                      chroma if keep else None)


def excess(li: LaserImage) -> np.ndarray:
    """(H, W) float32 ≥ 0: the laser channel's excess over the mean of the two others in
    ``li.bgr``, where a neutral board's pattern (black on white) cancels and the laser's
    light stays, also where the stripe runs along a square's edge."""
    return cv2.max(li.chroma, 0.0)
