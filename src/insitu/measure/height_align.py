"""The last step of locating a part: align the scan's height image to the reference's, seen
from above in the part's frame, with OpenCV's ECC (a Euclidean warp: a turn and a shift).

Point-to-plane ICP gets no hold in x, y from flat tops; the outline does, and a height image
holds it on both sides — the part's top inside, the table (or a lower step) outside. Scan
points are splatted onto the image and spread by a Gaussian (normalised convolution, so the
gaps between scan lines fill); the reference's exact height image gets the same blur. Pixels
without support all around (shadows beside walls, the scan's border) are left out, so a
one-sided edge cannot pull the fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

PX_MM = 0.1
SIGMA_MM = 0.5
MARGIN_MM = 4.0
SUPERSAMPLE = 4
"""Rays per pixel side when a mesh is seen from above: its edges land between pixels."""
SUPPORT = 0.8
"""A scan pixel is compared when its blurred sample weight is at least this share of the
typical weight (full support around it)."""


@dataclass(frozen=True, eq=False)
class HeightImage:
    """Heights seen from above on a grid of the part frame: ``z`` (H, W) float32 mm, the
    pixel (row r, column c) at x = x0_mm + c·px_mm, y = y0_mm + r·px_mm."""

    z: np.ndarray
    x0_mm: float
    y0_mm: float
    px_mm: float = PX_MM

    def blurred(self) -> np.ndarray:
        """``z`` under the splatting's Gaussian, float32 (cached)."""
        if "_blur" not in self.__dict__:
            s = SIGMA_MM / self.px_mm
            self.__dict__["_blur"] = cv2.GaussianBlur(self.z, (0, 0), s)
        return self.__dict__["_blur"]


def mesh_height_image(vertices: np.ndarray, triangles: np.ndarray, base_z: float,
                      px_mm: float = PX_MM) -> HeightImage:
    """The mesh (part frame, mm) seen from straight above, the table at ``base_z`` around it,
    over its footprint plus ``MARGIN_MM``: ray cast with Open3D, ``SUPERSAMPLE``² rays a
    pixel averaged (an edge between pixel centres is not rounded to one)."""
    import open3d as o3d

    v = np.asarray(vertices, np.float64)
    lo, hi = v[:, :2].min(axis=0) - MARGIN_MM, v[:, :2].max(axis=0) + MARGIN_MM
    xs, ys = np.arange(lo[0], hi[0], px_mm), np.arange(lo[1], hi[1], px_mm)
    sub = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5      # rays spread over a pixel
    X, Y = np.meshgrid((xs[:, None] + sub * px_mm).ravel(), (ys[:, None] + sub * px_mm).ravel())
    top = float(v[:, 2].max() + 1.0)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v.astype(np.float32)),
                        o3d.core.Tensor(np.asarray(triangles, np.uint32)))
    rays = np.zeros((X.size, 6), np.float32)
    rays[:, 0], rays[:, 1], rays[:, 2], rays[:, 5] = X.ravel(), Y.ravel(), top, -1.0
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    z = np.where(np.isfinite(t), top - t, base_z).reshape(len(ys), SUPERSAMPLE, len(xs),
                                                        SUPERSAMPLE).mean(axis=(1, 3))
    z = z.astype(np.float32)
    return HeightImage(z, float(xs[0]), float(ys[0]), px_mm)


def splat(points: np.ndarray, like: HeightImage) -> tuple[np.ndarray, np.ndarray]:
    """(heights (H, W) float32, support (H, W) bool) of ``points`` (N, 3), part frame, on
    ``like``'s grid: bilinear splats spread by the Gaussian and normalised; support where
    the spread weight is at least ``SUPPORT`` × its typical value."""
    h, w = like.z.shape
    c = (points[:, 0] - like.x0_mm) / like.px_mm
    r = (points[:, 1] - like.y0_mm) / like.px_mm
    inside = (c >= 0) & (c < w - 1) & (r >= 0) & (r < h - 1)
    c, r, z = c[inside], r[inside], points[inside, 2]
    c0, r0 = np.floor(c).astype(np.int64), np.floor(r).astype(np.int64)
    fc, fr = c - c0, r - r0
    W = np.zeros(h * w)
    Z = np.zeros(h * w)
    for dr, dc, wt in ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc),
                       (1, 0, fr * (1 - fc)), (1, 1, fr * fc)):
        idx = (r0 + dr) * w + (c0 + dc)
        W += np.bincount(idx, wt, h * w)
        Z += np.bincount(idx, wt * z, h * w)
    s = SIGMA_MM / like.px_mm
    Wb = cv2.GaussianBlur(W.reshape(h, w).astype(np.float32), (0, 0), s)
    Zb = cv2.GaussianBlur(Z.reshape(h, w).astype(np.float32), (0, 0), s)
    full = np.percentile(Wb[Wb > 0], 90) if (Wb > 0).any() else 1.0
    support = Wb >= SUPPORT * full
    return np.where(support, Zb / np.maximum(Wb, 1e-12), 0.0).astype(np.float32), support


def align(reference: HeightImage, points_part: np.ndarray,
          iterations: int = 60) -> tuple[float, np.ndarray] | None:
    """The small correction (angle_rad, (2,) shift mm) to apply, in the part frame, to
    ``points_part`` (N, 3) — scan points mapped into the part frame by an estimate of the
    pose — so that their height image matches the reference's: a corrected point is
    ``Rz(angle) @ p + shift`` (x, y only). None when ECC does not converge or too few
    pixels are supported."""
    img, support = splat(points_part, reference)
    if support.sum() < 500:
        return None
    warp = np.eye(2, 3, dtype=np.float32)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, iterations, 1e-6)
    try:
        _, warp = cv2.findTransformECC(reference.blurred(), img, warp, cv2.MOTION_EUCLIDEAN,
                                       crit, support.astype(np.uint8), 1)
    except cv2.error:
        return None
    # template pixel x ↦ scan pixel W(x): the scan's points sit at W of where they belong
    A, b = warp[:, :2].astype(np.float64), warp[:, 2].astype(np.float64) * reference.px_mm
    o = np.array([reference.x0_mm, reference.y0_mm])
    # W in mm: q ↦ A (q − o) + o + b; its inverse maps the scan's points home
    Ai = A.T
    angle = float(np.arctan2(Ai[1, 0], Ai[0, 0]))
    shift = o - Ai @ (o + b)
    return angle, shift


def splat_image(points: np.ndarray, part: np.ndarray, base_z: float,
                px_mm: float = PX_MM) -> HeightImage:
    """A scan's height image as a reference: ``points`` (N, 3) splatted over the footprint of
    ``part`` (its points above the table) plus ``MARGIN_MM``; unsupported pixels (shadows)
    take the table's height ``base_z``."""
    lo = part[:, :2].min(axis=0) - MARGIN_MM
    hi = part[:, :2].max(axis=0) + MARGIN_MM
    shape = (int(np.ceil((hi[1] - lo[1]) / px_mm)), int(np.ceil((hi[0] - lo[0]) / px_mm)))
    grid = HeightImage(np.zeros(shape, np.float32), float(lo[0]), float(lo[1]), px_mm)
    img, support = splat(points, grid)
    out = HeightImage(np.where(support, img, base_z).astype(np.float32), grid.x0_mm,
                      grid.y0_mm, px_mm)
    out.__dict__["_blur"] = out.z          # already spread like a scan
    return out
