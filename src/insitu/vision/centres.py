"""Sub-pixel centres of a laser line: one crossing per scan column (rows mode) or per row, by
one of the methods of :data:`CENTRE_METHODS`.

Every method uses the detection stage and keywords of :mod:`insitu.vision.detect`.
:func:`~insitu.vision.centroid.gray_centroid` (Li et al. §2.3, Eq. 7) is in
:mod:`insitu.vision.centroid`; :func:`~insitu.vision.steger.gaussian_peak` and
:func:`~insitu.vision.steger.steger` in :mod:`insitu.vision.steger`; :func:`line_centres`
dispatches on the table, takes the laser's light out of a colour image or a frame with a
laser-off frame (:mod:`insitu.vision.laser_image`) and handles lines that run along the
columns, found from the image's structure when not given (:func:`line_direction`).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from insitu.vision.centroid import gray_centroid
from insitu.vision.chains import longest_ridge
from insitu.vision.course import in_frame, off_the_excess, on_course, on_laser
from insitu.vision.detect import LineCentres
from insitu.vision.excess_fill import filled
from insitu.vision.laser_image import (
    CHANNELS,
    WHITE,
    ImageInputError,
    LaserImage,
    colour_margin,
    colour_reach,
    laser_image,
    noise_sigma,
    ridges,
    shrink,
)
from insitu.vision.profile import (
    as_image,
    gather,
    saturation_level,
)
from insitu.vision.rims import cut_cores
from insitu.vision.steger import gaussian_peak, steger
from insitu.vision.tracks import AmbiguousStripe

__all__ = ["CENTRE_METHODS", "CHANNELS", "CentreMethod", "ImageInputError", "LineCentres",
           "as_gray", "gaussian_peak", "gray_centroid", "line_centres", "line_direction",
           "photo_centres", "steger", "UncertainLine"]


def as_gray(image, channel: str = "auto") -> np.ndarray:
    """The (H, W) image the centres are found in: ``image`` itself if gray, else the laser's
    channel of an (H, W, 3) BGR (or (H, W, 1)) image: "r", "g", "b", or "auto", the channel
    whose excess over the other two forms the strongest thin ridges
    (:func:`~insitu.vision.laser_image.laser_image`). ImageInputError (one line) for any
    other shape or channel name."""
    return laser_image(image, channel).gray


def line_direction(image: np.ndarray) -> str:
    """"rows" if the line runs mostly along the rows (crosses more columns than rows), else
    "cols", from the image's structure: the orientation of the gradient energy (structure
    tensor) of the white top-hat of the shrunk frame (:func:`~insitu.vision.laser_image.ridges`),
    where a bright board or background has gone and only thin ridges stay. A line along the
    rows has its gradients across them (along y). ≈ 2 ms a 5 MPix uint8 frame
    (benchmarks/centres_speed.py)."""
    hat = ridges(shrink(as_image(image)))
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
                           "Steger's Hessian ridge detector (ours, the default)",
                           {"across": True}),
}


COURSE = 0.06
"""Half the span of scan lines, of the frame's shorter side, over which a photograph's stripe
is taken as straight (:func:`~insitu.vision.course.on_course`): a stretch of centres slid
onto the rim of a dark dot or the edge of a square is shorter."""
PHOTO_RUN = 20
"""Least columns (or rows) of a stripe in anyone's photograph (:func:`photo_centres`)."""
CLIPPED = 0.98
"""The fraction of full scale from which a photograph's pixel counts as clipped
(:func:`line_centres`' ``clipped``): JPEG rings the inside of a clipped area a few gray values
below full scale (quality 75–95: the 1st percentile of a clipped stripe's pixels at 249–252 of
255, median over stripes), and a clipped core whose pixels count as unclipped has its
flanks fitted across the noisy plateau, which puts the centre off its middle."""
FRINGE_MARGIN = 1.0
"""Least laser colour of a photograph's line over the colour fringes at its edges
(:func:`photo_centres`): on the real sets of benchmarks/real_lines.py the lines measured
right carry 1.5 – 4 times as much, those lost in the fringes of a checkerboard 0.3 – 0.8."""


class UncertainLine(ImageInputError):
    """A photograph whose line the laser's colour cannot tell from the edges of the scene."""


def line_centres(image: np.ndarray, method: str = "gray", direction: str | None = None,
                 band=None, channel: str = "auto", laser_off=None,
                 pixel_bits: int | None = None, clipped: float = 1.0, **kw) -> LineCentres:
    """Centres by ``method`` (a key of :data:`CENTRE_METHODS`) in image coordinates.

    image: (H, W) gray or (H, W, 3) BGR; channel, laser_off (the frame with the laser off,
    subtracted), pixel_bits: :func:`~insitu.vision.laser_image.laser_image` (a colour image's
    peaks are taken only where laser-coloured light lies within reach). A colour image with
    channel "auto" is measured in its laser's channel, or in the sum of its channels when the
    laser's channel is clipped at most of the stripe's peaks (a halo clips it; the core clips
    white, the halo does not) or the sum holds the longer stripe (where it is clipped white, a
    peak needs a third of the contrast, and where two channels are clipped the sum's noise
    is the third's: detect's ``white``, ``quiet``); peak and contrast are then the channels'
    mean, on the frame's scale. direction: "rows" (one
    point per column), "cols" (one per row: the frame is transposed and u, v swapped back) or
    None (auto, :func:`line_direction`). band: (lo, hi) allowed range of the cross coordinate
    per scan line (v per column, or u per row for "cols"). clipped: the fraction of full
    scale from which a pixel counts as clipped (a JPEG's clipped areas ring a few gray values
    below full scale). kw: passed to the method. ImageInputError for another method,
    direction, channel or image shape.
    """
    _check(method, direction)
    return _centres_in(laser_image(image, channel, laser_off, pixel_bits), method, direction,
                       band, clipped, kw)


def _check(method: str, direction: str | None) -> None:
    if method not in CENTRE_METHODS:
        raise ImageInputError(f"centre method {method!r}: expected one of "
                              f"{', '.join(CENTRE_METHODS)}")
    if direction not in (None, "rows", "cols"):
        raise ImageInputError(f"direction {direction!r}: expected rows, cols or auto")


def _centres_in(li: LaserImage, method, direction, band, clipped, kw,
                colour: bool = False) -> LineCentres:
    """:func:`line_centres` in the laser's light ``li``; colour (a photograph): the centres
    kept on the stripe's course (:mod:`insitu.vision.course`), those of clipped cores cut by a
    dark mark's edge moved to the line (:func:`~insitu.vision.rims.cut_cores`), and the gaps
    of the stripe filled from the laser channel's excess over the others
    (:func:`~insitu.vision.excess_fill.filled`)."""
    fn = CENTRE_METHODS[method].find
    img, allow = li.gray, li.allow
    if direction is None:
        direction = line_direction(img if li.ridge is None else li.ridge)
    def scaled(fs):
        return dict(kw, scale=fs, **({"saturation": clipped * fs} if clipped < 1 else {}))

    in_sum = li.total is not None and _in_sum(li, direction, band, allow, kw, scaled)
    masks, white = {}, None
    if (in_sum or colour) and li.bgr is not None:
        b, g, r = cv2.split(li.bgr)
        white = cv2.min(cv2.min(b, g), r) >= WHITE * li.full_scale
    if in_sum and white is not None:
        masks = {"white": white, "quiet": _quiet(li.bgr, li.total, clipped * li.full_scale)}
    if masks and method in _FLAT_TOPS:
        masks["clip"] = cv2.max(cv2.max(b, g), r) >= clipped * li.full_scale
    c = _along(fn, li.total if in_sum else img, direction, band, allow,
               scaled((3 if in_sum else 1) * li.full_scale) | masks)
    if in_sum:
        c = replace(c, peak=c.peak / 3, contrast=c.contrast / 3, full_scale=li.full_scale)
    if colour and li.bgr is not None:
        c = on_laser(c, li.bgr, CHANNELS[li.channel], WHITE * li.full_scale,
                     direction == "rows", colour_reach(img.shape)[0])
    if colour:
        c = on_course(in_frame(c, img.shape), direction == "rows", COURSE * min(img.shape))
        c = cut_cores(c, li.total if in_sum else img, clipped * (3 if in_sum else 1)
                      * li.full_scale, direction == "rows")
    def fill(c):
        return filled(c, li, fn, direction == "rows", scaled, white, PHOTO_RUN)
    if colour and white is not None:
        c = off_the_excess(c, direction == "rows", COURSE * min(img.shape), PHOTO_RUN, fill)
    return c


def _quiet(bgr: np.ndarray, total: np.ndarray, level: float) -> np.ndarray:
    """(H, W) float32: the noise of ``total``, the sum of ``bgr``'s channels, as a fraction
    of its noise over the frame: where two channels are clipped (≥ ``level``), the third's
    noise over the sum's (a clipped channel carries none), 1 elsewhere (detect's ``quiet``;
    each sigma measured on the whole frame)."""
    ch = cv2.split(bgr)
    share = [min(noise_sigma(c) / max(noise_sigma(total), 1e-6), 1.0) for c in ch]
    code = np.zeros(total.shape, np.uint8)                  # bit k: channel k clipped
    for k, c in enumerate(ch):
        cv2.bitwise_or(code, cv2.bitwise_and(cv2.compare(c, level, cv2.CMP_GE), 1 << k), dst=code)
    lut = np.ones(256, np.float32)
    for k in range(3):
        for i in range(8):
            if i | (1 << k) == 7:                         # the two others clipped
                lut[i] = min(lut[i], share[k])
    return cv2.LUT(code, lut)


_FLAT_TOPS = ("gaussian",)
"""Methods given a colour frame's pixels clipped in some channel (``clip``) when it is measured
in the sum of its channels (:func:`~insitu.vision.steger.gaussian_peak`): a 3-point fit on
the flat top that leaves in the sum jumps between its noisy maxima (up to ≈ 2 px; spent seed
8008 of benchmarks/clipped_white.py). Steger's smoothing and the gray centroid's sum are
not moved by it."""


_DETECTION = ("band", "min_peak", "min_contrast", "snr", "continuity", "extend_ends", "upper",
              "min_run", "ridge", "noise", "median", "window")


def _in_sum(li: LaserImage, direction, band, allow, kw, scaled) -> bool:
    """Whether a colour frame's stripe is measured in the sum of its channels: where the
    laser's channel is clipped at most of the stripe's peaks in it, or the sum holds the
    longer stripe — both judged on the gray centroid's centres (with the method's detection
    keywords; on every second scan line when no band is given), so that every method
    measures in the same image."""
    probe = dict(CENTRE_METHODS["gray"].defaults,
                 **{k: bool(v) if k == "ridge" else v for k, v in kw.items()
                    if k in _DETECTION})
    every = (slice(None), slice(None, None, 2)) if direction == "rows" else \
        (slice(None, None, 2), slice(None))
    if band is not None:
        every = (slice(None), slice(None))
    allow = None if allow is None else allow[every]
    c = _along(gray_centroid, li.gray[every], direction, band, allow,
               _gray(scaled(li.full_scale)) | probe)
    if len(c) and np.mean(c.saturated) > 0.5:
        return True
    t = _along(gray_centroid, li.total[every], direction, band, allow,
               _gray(scaled(3 * li.full_scale)) | probe)
    if len(t) and np.mean(_clipped_at(li.gray[every], t, scaled(li.full_scale))) > 0.5:
        return True
    return _stripe_length(t, direction) > _stripe_length(c, direction)


def _gray(kw: dict) -> dict:
    """The keywords of ``kw`` that :func:`gray_centroid` takes (a method's own, such as
    Steger's ``across``, left out)."""
    return {k: v for k, v in kw.items() if k in _GRAY_KEYS}


_GRAY_KEYS = frozenset(inspect.signature(gray_centroid).parameters)


def _clipped_at(img: np.ndarray, c: LineCentres, kw) -> np.ndarray:
    """(n,) bool: whether ``img`` (H, W), the laser's channel, is clipped (``kw``'s
    saturation, else its scale) within ±2 px of each centre ``c`` found in the sum of the
    channels: there the laser's channel holds a clipped plateau (a halo that clips it on a
    bright board) wider than a ridge, where its own centres go to a thinner, weaker ridge
    (a reflection of the stripe) and the sum's go to the stripe."""
    level = saturation_level(img, kw.get("saturation"), kw["scale"])
    rows = np.round(c.v).astype(np.int64)[None, :] + np.arange(-2, 3)[:, None]
    g, _ = gather(img, rows, np.round(c.u).astype(np.int64))
    return g.max(axis=0) >= level


def _stripe_length(c: LineCentres, direction: str) -> int:
    """Scan lines on the longest ridge of centres ``c`` of a line running ``direction``."""
    return longest_ridge(c.u, c.v) if direction == "rows" else longest_ridge(c.v, c.u)


def _along(fn, img, direction, band, allow, kw) -> LineCentres:
    """``fn``'s centres of the line in ``img`` running ``direction``, in image coordinates;
    UncertainLine naming both where tracks rival the stripe (``ridge="alone"``,
    :class:`~insitu.vision.tracks.AmbiguousStripe`)."""
    try:
        return _transposed(fn, img, direction, band, allow, kw)
    except AmbiguousStripe as e:
        scan, cross = ("columns", "rows") if direction == "rows" else ("rows", "columns")
        (a, b), (c, d) = e.rows
        raise UncertainLine(
            f"two laser lines, at {cross} {a}–{b} and {c}–{d}, run side by side in {scan} "
            f"{e.scan[0]}–{e.scan[1]} (a reflection of the stripe?): which one "
            "is the stripe cannot be told (give a laser-off photograph, --background, or "
            "crop the image to the board)") from None


def _transposed(fn, img, direction, band, allow, kw) -> LineCentres:
    """``fn``'s centres of the line in ``img`` running ``direction``, in image coordinates."""
    if direction == "rows":
        return fn(img, band=band, allow=allow, **kw)
    kw = dict(kw, **{k: kw[k].T for k in ("white", "quiet", "clip") if k in kw})
    t = fn(cv2.transpose(img), band=band, allow=None if allow is None else allow.T, **kw)
    return LineCentres(t.v, t.u, t.peak, t.width, t.contrast, t.saturated, t.ambiguous,
                       t.full_scale)


def photo_centres(image: np.ndarray, method: str = "steger", direction: str | None = None,
                  channel: str = "auto", laser_off=None,
                  pixel_bits: int | None = None) -> LineCentres:
    """Centres of a laser line in anyone's photograph, as ``insitu centres`` finds them: the
    method's :attr:`~CentreMethod.defaults`, per scan line the thin ridge on the longest
    track (``ridge``, :mod:`insitu.vision.detect`), stripes shorter than :data:`PHOTO_RUN`
    scan lines dropped (a glint, a lamp, a short edge). Arguments: :func:`line_centres`.
    UncertainLine when, without a laser-off frame, the line's laser colour is less than
    :data:`FRINGE_MARGIN` times the colour fringes at the frame's edges
    (:func:`~insitu.vision.laser_image.colour_margin`): its centres could lie on any edge."""
    _check(method, direction)
    kw = dict(CENTRE_METHODS[method].defaults)
    li = laser_image(image, channel, laser_off, pixel_bits)
    c = _centres_in(li, method, direction, None, CLIPPED,
                    dict(kw, min_run=PHOTO_RUN, ridge="alone"),
                    colour=True)
    margin = colour_margin(li, c.u, c.v) if laser_off is None else np.inf
    if margin < FRINGE_MARGIN:
        raise UncertainLine(f"the line's laser colour is {margin:.2f} × the colour fringes at "
                            "the image's edges: it cannot be told from them (give a laser-off "
                            "photograph, --background)")
    return c
