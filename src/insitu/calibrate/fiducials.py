"""Centres of marked circles (fiducials) on a flat plate, for the marked-fiducial variant of the
field calibration (Mikkelstrup et al. §2.4: circles are marked on a plate, imaged, and their
centres found).

The frame's dark, thin features are picked out as the contrast against a grey closing of the
frame (a background wider than a mark's line). Around where each commanded circle should be,
the largest connected dark feature is taken, every pixel of it is back-projected onto the plate
(so perspective and lens distortion do not bias the centre), and a circle is fitted to those
plate points weighted by their contrast (algebraic least squares, Kåsa). A feature whose fitted
diameter is far from the marked one, or that is cut by the image border, gives no centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.geometry.camera import CameraModel


@dataclass(frozen=True)
class CircleSettings:
    """min_contrast: least darkening (fraction of the local background) of a mark pixel;
    search_mm: how far a circle may land from its command; diameter_tolerance: accepted
    relative difference between fitted and marked diameter; kernel_mm: background
    (closing) width, wider than the mark's line and narrower than the circle."""

    min_contrast: float = 0.25
    search_mm: float = 4.0
    diameter_tolerance: float = 0.15
    kernel_mm: float = 0.8


def _circle_fit(xy: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, float]:
    """Weighted algebraic circle fit: centre (2,), radius (mm)."""
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy ** 2).sum(1)
    sw = np.sqrt(w)
    sol, *_ = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)
    c = sol[:2]
    return c, float(np.sqrt(max(sol[2] + c @ c, 0.0)))


def find_circles(image: np.ndarray, camera: CameraModel, plate_z: float,
                 commands: np.ndarray, diameter_mm: float,
                 settings: CircleSettings = CircleSettings()
                 ) -> tuple[np.ndarray, list[str | None]]:
    """Centres (N, 2) mm on the plate z = ``plate_z`` of the circles commanded at
    ``commands`` (N, 2) mm (NaN where none was found) and, per circle, None or why not.
    ``image`` (H, W) uint8/uint16; ``camera``: the operator's calibrated camera."""
    Q = np.asarray(commands, np.float64).reshape(-1, 2)
    img = np.asarray(image, np.float32)
    expected = camera.project(np.column_stack([Q, np.full(len(Q), float(plate_z))]))
    px_per_mm = _scale(camera, Q, plate_z)
    k = max(3, int(round(settings.kernel_mm * px_per_mm)) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    img = cv2.GaussianBlur(img, (3, 3), 0.7)
    bg = cv2.morphologyEx(img, cv2.MORPH_CLOSE, kernel)
    contrast = 1.0 - img / np.maximum(bg, 1.0)
    dark = ((contrast > settings.min_contrast) & (bg > 8.0)).astype(np.uint8)
    half = int(np.ceil((settings.search_mm + diameter_mm) * px_per_mm))
    H, W = dark.shape
    centres = np.full_like(Q, np.nan)
    reasons: list[str | None] = []
    for i, (u, v) in enumerate(expected):
        if not (np.isfinite(u) and np.isfinite(v) and camera.in_image(np.array([[u, v]]))[0]):
            reasons.append("outside the camera's view")
            continue
        if not camera.in_image(np.array([[u, v]]), half)[0]:
            reasons.append("too close to the image border to search")
            continue
        u0, v0 = int(round(u)) - half, int(round(v)) - half
        roi = dark[v0:v0 + 2 * half + 1, u0:u0 + 2 * half + 1]
        n, labels, stats, _ = cv2.connectedComponentsWithStats(roi, connectivity=8)
        if n < 2:
            reasons.append("no mark found")
            continue
        j = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        x, y, w, h = stats[j, :4]
        if x == 0 or y == 0 or x + w >= roi.shape[1] or y + h >= roi.shape[0]:
            reasons.append("the mark is cut by the search window (landed too far off?)")
            continue
        vv, uu = np.nonzero(labels == j)
        uv = np.column_stack([uu + u0, vv + v0]).astype(np.float64)
        o, d = camera.rays(uv)
        s = (plate_z - o[2]) / d[:, 2]
        xy = o[:2] + s[:, None] * d[:, :2]
        c, r = _circle_fit(xy, contrast[vv + v0, uu + u0].astype(np.float64))
        if abs(2 * r / diameter_mm - 1) > settings.diameter_tolerance:
            reasons.append(f"the mark is {2 * r:.2f} mm wide, not a {diameter_mm:g} mm circle")
            continue
        centres[i] = c
        reasons.append(None)
    return centres, reasons


def _scale(camera: CameraModel, Q: np.ndarray, plate_z: float) -> float:
    """Pixels per mm on the plate near the middle of ``Q``."""
    c = np.nanmedian(Q, axis=0) if len(Q) else np.zeros(2)
    p = np.array([[c[0], c[1], plate_z], [c[0] + 1.0, c[1], plate_z]])
    uv = camera.project(p)
    s = float(np.linalg.norm(uv[1] - uv[0]))
    return s if np.isfinite(s) and s > 0 else 10.0
