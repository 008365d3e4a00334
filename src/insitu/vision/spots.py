"""Laser spot centres in camera frames (Le & Quinsat 2020, §5.2).

The frame is smoothed by a 2-D Gaussian filter, binarised at ``T = bg + (I_max - bg) / 1.1``
(the paper's ``I_max / 1.1``, taken relative to the background so that room light does not
move the threshold) to find the spot, and the spot centre is the centre of gravity of the
filtered intensity above the background. Our spots are small (σ ≈ 1 px on the full-size
sensor), so by default the centre of gravity is taken over a window grown from the binarised
core down to a few % of the peak (``region="window"``): over the core alone (``"threshold"``,
the paper's exact recipe) the centre locks to pixels. ``method="ellipse"`` fits an ellipse
(cv2.fitEllipse) to the sub-pixel iso-contour at ``ellipse_level`` of the peak (the paper's
method m1.2).

Pixels: origin at the centre of the top-left pixel, u right, v down (OpenCV).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from insitu.errors import CalibrationError


@dataclass(frozen=True)
class SpotSettings:
    """How spots are found and centred.

    sigma_px: σ of the Gaussian filter, px. threshold_ratio: the core is ``> bg + (I_max - bg)
    / threshold_ratio``. region: centre of gravity over the core (``"threshold"``) or over the
    connected window ``> window_level`` × amplitude around it, dilated by 2 px (``"window"``).
    min_contrast_dn: least peak height above background (None: 8 DN or 8 × the noise, the
    larger). second_spot_ratio: another blob this high (× amplitude) means several spots.
    max_saturated_px: more clipped pixels than this is saturated beyond use. roi_px: half
    size of the window processed around the peak.
    """

    sigma_px: float = 1.0
    threshold_ratio: float = 1.1
    method: Literal["centroid", "ellipse"] = "centroid"
    region: Literal["window", "threshold"] = "window"
    window_level: float = 0.02
    ellipse_level: float = 0.5
    min_contrast_dn: float | None = None
    second_spot_ratio: float = 0.5
    max_saturated_px: int = 50
    roi_px: int = 24


@dataclass(frozen=True)
class Spot:
    """A spot centre (u, v), px, with what was seen: filtered peak and local background (DN),
    pixels in the binarised core and clipped (saturated) pixels."""

    u: float
    v: float
    peak: float
    background: float
    area_px: int
    saturated_px: int

    @property
    def uv(self) -> np.ndarray:
        """(2,) float64 pixel centre."""
        return np.array([self.u, self.v])


def _saturation(image: np.ndarray) -> float:
    return float(np.iinfo(image.dtype).max) if image.dtype.kind in "ui" else np.inf


def room_light(filt: np.ndarray, step: int = 8) -> np.ndarray:
    """(H, W) float32: the frame's slowly varying background — the median of 5 × 5 blocks of
    ``step`` px, smoothly interpolated; a spot of a few px leaves no trace in it."""
    H, W = filt.shape
    small = cv2.resize(filt, (max(W // step, 1), max(H // step, 1)), interpolation=cv2.INTER_AREA)
    small = cv2.medianBlur(small, 5) if min(small.shape) >= 5 else small
    return cv2.resize(small, (W, H), interpolation=cv2.INTER_LINEAR)


def _component_at(mask: np.ndarray, v: int, u: int) -> np.ndarray:
    """The 8-connected component of ``mask`` (bool) containing pixel (v, u)."""
    _, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    return labels == labels[v, u] if mask[v, u] else np.zeros_like(mask)


def find_spot(image: np.ndarray, settings: SpotSettings = SpotSettings(),
              where: str = "image") -> Spot:
    """The centre of the one laser spot in ``image`` ((H, W) uint8/uint16 or float).

    Raises CalibrationError (naming ``where``) if there is no spot (peak too low above the
    background), several spots, a spot saturated over more than ``max_saturated_px`` or one
    cut off by the image border.
    """
    s = settings
    img = np.asarray(image)
    if img.ndim != 2 or img.size == 0:
        raise CalibrationError(f"{where}: expected a (H, W) grey image, got shape {img.shape}")
    H, W = img.shape
    # Whole frame, cheaply: find the peak and check there is one spot, over the room light
    # (shaded and textured across the frame) taken away.
    small = img if img.dtype == np.uint8 else img.astype(np.float32)
    filt = cv2.GaussianBlur(small, (0, 0), s.sigma_px).astype(np.float32, copy=False)
    flat = filt - room_light(filt)
    sample = flat[::8, ::8]
    noise = 1.4826 * float(np.median(np.abs(sample - np.median(sample))))
    _, amp, _, (pu, pv) = cv2.minMaxLoc(flat)
    min_contrast = s.min_contrast_dn if s.min_contrast_dn is not None else max(8.0, 8.0 * noise)
    if amp < min_contrast:
        raise CalibrationError(f"{where}: no laser spot found (brightest point {amp:.1f} DN "
                               f"above the background, need {min_contrast:.1f})")
    bright = cv2.findNonZero((flat > s.second_spot_ratio * amp).astype(np.uint8))
    far = bright.reshape(-1, 2)[np.abs(bright.reshape(-1, 2) - (pu, pv)).max(1) > s.roi_px]
    if len(far):
        fu, fv = far[np.argmax(filt[far[:, 1], far[:, 0]])]
        raise CalibrationError(f"{where}: several spots where one was expected: at ({pu}, {pv})"
                               f" px and at ({fu}, {fv}) px ({len(far)} bright px away from "
                               "the brightest spot)")
    # Around the peak, in floating point.
    r = s.roi_px
    v0, v1, u0, u1 = max(pv - r, 0), min(pv + r + 1, H), max(pu - r, 0), min(pu + r + 1, W)
    roi = img[v0:v1, u0:u1].astype(np.float64)
    froi = cv2.GaussianBlur(roi, (0, 0), s.sigma_px, borderType=cv2.BORDER_REPLICATE)
    border = np.concatenate([froi[0], froi[-1], froi[1:-1, 0], froi[1:-1, -1]])
    bg_local = float(np.median(border))
    cv_, cu = pv - v0, pu - u0
    amp = float(froi[cv_, cu]) - bg_local
    if amp <= 0:
        raise CalibrationError(f"{where}: no laser spot found (no peak above the local "
                               f"background at ({pu}, {pv}) px)")
    core = _component_at(froi > bg_local + amp / s.threshold_ratio, cv_, cu)
    core[cv_, cu] = True
    saturated = int(np.count_nonzero(roi >= _saturation(img)))
    if saturated > s.max_saturated_px:
        raise CalibrationError(f"{where}: spot saturated over {saturated} px (at most "
                               f"{s.max_saturated_px}): reduce the exposure or laser power")
    if s.method == "ellipse":
        u, v = _ellipse_centre(froi, bg_local + s.ellipse_level * amp, cv_, cu, where,
                               (v0, v1, u0, u1), (H, W))
    else:
        if s.region == "threshold":
            region = core
        else:
            noise_local = 1.4826 * float(np.median(np.abs(border - bg_local)))
            low = max(s.window_level * amp, 3.0 * noise_local)
            region = _component_at(froi > bg_local + low, cv_, cu)
            region = cv2.dilate(region.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        _check_inside(region, (v0, v1, u0, u1), (H, W), pu, pv, where)
        w = np.where(region, np.maximum(froi - bg_local, 0.0), 0.0)
        total = w.sum()
        vv, uu = np.mgrid[0:w.shape[0], 0:w.shape[1]]
        u, v = float((w * uu).sum() / total), float((w * vv).sum() / total)
    return Spot(u + u0, v + v0, float(froi[cv_, cu]), bg_local, int(core.sum()), saturated)


def _check_inside(region: np.ndarray, box: tuple[int, int, int, int], shape: tuple[int, int],
                  pu: int, pv: int, where: str) -> None:
    """CalibrationError if ``region`` (of the window ``box`` = v0, v1, u0, u1 of an image of
    ``shape``) reaches the image border: the spot is cut off and its centre biased."""
    v0, v1, u0, u1 = box
    H, W = shape
    if ((v0 == 0 and region[0].any()) or (v1 == H and region[-1].any())
            or (u0 == 0 and region[:, 0].any()) or (u1 == W and region[:, -1].any())):
        raise CalibrationError(f"{where}: the spot at ({pu}, {pv}) px is cut off by the image "
                               "border")


def _ellipse_centre(f: np.ndarray, level: float, cv_: int, cu: int, where: str,
                    box: tuple[int, int, int, int], shape: tuple[int, int]
                    ) -> tuple[float, float]:
    """Centre of the ellipse fitted to the sub-pixel iso-contour ``f == level`` around
    (cv_, cu): crossings interpolated linearly between neighbouring pixels."""
    inside = _component_at(f > level, cv_, cu)
    _check_inside(inside, box, shape, cu + box[2], cv_ + box[0], where)
    near = cv2.dilate(inside.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    pts = []
    for axis in (0, 1):
        a, b = (f[:-1], f[1:]) if axis == 0 else (f[:, :-1], f[:, 1:])
        ia, ib = (inside[:-1], inside[1:]) if axis == 0 else (inside[:, :-1], inside[:, 1:])
        na = near[:-1] if axis == 0 else near[:, :-1]
        cross = (ia != ib) & na
        i, j = np.nonzero(cross)
        t = (level - a[i, j]) / (b[i, j] - a[i, j])
        pts.append(np.column_stack([j, i + t]) if axis == 0 else np.column_stack([j + t, i]))
    pts = np.concatenate(pts).astype(np.float32)
    if len(pts) < 5:
        raise CalibrationError(f"{where}: the spot is too small for an ellipse fit "
                               f"({len(pts)} contour points, need 5)")
    (u, v), _, _ = cv2.fitEllipse(pts)
    return float(u), float(v)
