"""A part seen from straight above: heights on a grid of its own frame, the table around it
— exactly from a mesh (ray cast), or from a scan (its points splatted). The edge step of
locating (:mod:`insitu.locate.edge_align`) finds the reference's edges on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from scipy.interpolate import griddata
from scipy.spatial import cKDTree

PX_MM = 0.1
SIGMA_MM = 0.25
MARGIN_MM = 4.0
SUPERSAMPLE = 4
"""Rays per pixel side when a mesh is seen from above: its edges land between pixels."""
NORMAL_SIGMA_PX = 1.5
"""Blur before the gradient that gives an edge's normal: a sharp step differenced over a few
pixels alone turns every edge's normal to a multiple of 45° (an insert's 60° sides read as
46°)."""
COVER_MM = 0.3
"""A pixel is measured when a scan point lies within this, or within ``COVER_GAP`` of the
gap between the scan's lines where that is more (:func:`line_gap_mm`)."""
COVER_GAP = 0.6
"""Half the gap between two lines and a little: with lines 1 mm apart (another renderer's
recording, every second line) a 0.3 mm cover left 18 % of the arc's top at the table's
height, in stripes between the lines, each a false edge."""


@dataclass(frozen=True, eq=False)
class HeightImage:
    """Heights seen from above on a grid of the part frame: ``z`` (H, W) float32 mm, the
    pixel (row r, column c) at x = x0_mm + c·px_mm, y = y0_mm + r·px_mm."""

    z: np.ndarray
    x0_mm: float
    y0_mm: float
    px_mm: float = PX_MM

    def pixel(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(columns, rows) (...) of part-frame points ``xy`` (..., ≥2) mm on this grid."""
        return (xy[..., 0] - self.x0_mm) / self.px_mm, (xy[..., 1] - self.y0_mm) / self.px_mm

    @cached_property
    def slope(self) -> tuple[np.ndarray, np.ndarray]:
        """(∂z/∂x, ∂z/∂y) (H, W) float32 of the heights blurred by ``NORMAL_SIGMA_PX``: its
        direction across a straight edge is the edge's normal, at any angle."""
        z = cv2.GaussianBlur(np.asarray(self.z, np.float32), (0, 0), NORMAL_SIGMA_PX)
        return (cv2.Sobel(z, cv2.CV_32F, 1, 0, ksize=3) / (8 * self.px_mm),
                cv2.Sobel(z, cv2.CV_32F, 0, 1, ksize=3) / (8 * self.px_mm))


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


def splat(points: np.ndarray, like: HeightImage, cover_mm: float = COVER_MM
          ) -> tuple[np.ndarray, np.ndarray]:
    """(heights (H, W) float32, measured (H, W) bool) of ``points`` (N, 3), part frame, on
    ``like``'s grid: bilinear splats spread by a Gaussian of ``SIGMA_MM`` and normalised
    (the gaps between scan lines fill); measured within ``cover_mm`` of a point."""
    h, w = like.z.shape
    c, r = like.pixel(points)
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
    support = cv2.dilate((W.reshape(h, w) > 0).astype(np.uint8),
                         _disk(cover_mm / like.px_mm)).astype(bool)
    z_img = Zb / np.maximum(Wb, 1e-12)
    if cover_mm > COVER_MM:          # lines further apart than the Gaussian bridges
        rows, cols = np.nonzero(support)
        lin = griddata(np.column_stack([c, r]), z, (cols, rows), method="linear")
        z_img[rows, cols] = np.where(np.isfinite(lin), lin, z_img[rows, cols])
    return np.where(support, z_img, 0.0).astype(np.float32), support


def _disk(radius_px: float) -> np.ndarray:
    n = int(np.ceil(radius_px))
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * n + 1, 2 * n + 1))


def sample(images, cols: np.ndarray, rows: np.ndarray) -> list[np.ndarray]:
    """Each of ``images`` (H, W) at the fractional pixels (cols, rows) (N,), bilinear."""
    n = len(cols)
    k = -(-n // 1024) * 1024                 # cv2.remap takes under 32767 rows: fold them
    mx = np.zeros(k, np.float32)
    my = np.zeros(k, np.float32)
    mx[:n], my[:n] = cols, rows
    return [cv2.remap(np.asarray(im, np.float32), mx.reshape(-1, 1024), my.reshape(-1, 1024),
                      cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()[:n]
            .astype(np.float64) for im in images]


def splat_image(points: np.ndarray, part: np.ndarray, base_z: float,
                px_mm: float = PX_MM, lines: np.ndarray | None = None) -> HeightImage:
    """A scan's height image as a reference: ``points`` (N, 3) splatted over the footprint of
    ``part`` (its points above the table) plus ``MARGIN_MM``; unsupported pixels (shadows)
    take the table's height ``base_z``. ``lines`` (N,): each point's scan line, whose gap
    widens the cover (:data:`COVER_GAP`; None: ``COVER_MM``)."""
    lo = part[:, :2].min(axis=0) - MARGIN_MM
    hi = part[:, :2].max(axis=0) + MARGIN_MM
    shape = (int(np.ceil((hi[1] - lo[1]) / px_mm)), int(np.ceil((hi[0] - lo[0]) / px_mm)))
    grid = HeightImage(np.zeros(shape, np.float32), float(lo[0]), float(lo[1]), px_mm)
    cover = COVER_MM if lines is None else max(COVER_MM, COVER_GAP * line_gap_mm(points, lines))
    img, support = splat(points, grid, cover)
    return HeightImage(np.where(support, img, base_z).astype(np.float32), grid.x0_mm,
                       grid.y0_mm, px_mm)


def line_gap_mm(points: np.ndarray, lines: np.ndarray, sample: int = 2000) -> float:
    """How far apart a scan's lines lie, mm: the median distance from a point (of ``sample``
    of ``points`` (N, 3)) to the nearest point in x, y on another line (``lines`` (N,));
    0 when there is one line."""
    lines = np.asarray(lines)
    if len(np.unique(lines)) < 2:
        return 0.0
    tree = cKDTree(points[:, :2])
    at = np.arange(0, len(points), max(1, len(points) // sample))
    k = min(len(points), 128)
    dist, idx = tree.query(points[at, :2], k=k)
    other = lines[np.minimum(idx, len(points) - 1)] != lines[at, None]
    near = np.where(other, dist, np.inf).min(axis=1)
    return float(np.median(near[np.isfinite(near)])) if np.isfinite(near).any() else 0.0
