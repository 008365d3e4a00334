"""The camera's image of a mark, rectified onto the marked surface: an orthographic picture in
the mark's own frame, the oblique view and the surface's shape undone.

The mark's frame is the pattern's plane as placed (world x, y before projection): a point
``origin + u·axes[0] + v·axes[1]``, u, v mm. Picture pixel (row r, column c) has its centre
at u = c·px_mm, v = (H − r)·px_mm (v up in the picture, as :func:`.verify.render` draws the
plan). For every pixel the surface point it shows is found as the job was projected —
planar: x, y kept, z from the measured surface; wrap: the equal-arc-length map of
:mod:`.project` (lengths along the surface equal the pattern's) — and projected through the
calibrated camera (distortion included); ``cv2.remap`` samples the frame there. A pixel is
masked (NaN) where the cloud does not show the surface, where the point falls off the frame
and where the measured surface stands between it and the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from insitu.geometry.camera import CameraModel
from insitu.marking.project import _MAX_GRID, ArcLengthMap, Projection, _GradientGrid
from insitu.marking.surface import Surface
from insitu.patterns.model import Pattern

MAX_PX = 1200          # the picture's longer side at most, px
_OCCLUSION_TOL_MM = 0.2
_WRAP_GRID_MM = 0.25     # the wrap map's gradient grid at least this coarse (smooth surfaces)


@dataclass(frozen=True)
class MarkFrame:
    """``origin`` (2,) world x, y mm of u = v = 0; ``axes`` (2, 2) unit rows u, v;
    ``size_mm`` (u, v) extent; ``px_mm`` mm per picture pixel."""

    origin: np.ndarray
    axes: np.ndarray
    size_mm: tuple[float, float]
    px_mm: float

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the picture, px."""
        w, h = (int(math.ceil(s / self.px_mm)) for s in self.size_mm)
        return h, w

    def pattern_xy(self) -> np.ndarray:
        """(H, W, 2) pattern-plane world x, y mm of every pixel centre."""
        h, w = self.shape
        u = np.arange(w) * self.px_mm
        v = (h - np.arange(h)) * self.px_mm
        uu, vv = np.meshgrid(u, v)
        return self.origin + uu[..., None] * self.axes[0] + vv[..., None] * self.axes[1]

    def to_uv(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) pattern-plane world x, y mm → (N, 2) u, v mm."""
        return (np.asarray(xy, np.float64) - self.origin) @ self.axes.T

    def to_pixels(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) u, v mm → (N, 2) picture column, row (float)."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        return np.column_stack([uv[:, 0] / self.px_mm, self.shape[0] - uv[:, 1] / self.px_mm])


def camera_px_per_mm(camera: CameraModel, point: np.ndarray, axes: np.ndarray) -> float:
    """The camera's finest resolution at world ``point`` (3,) along the two in-plane ``axes``
    (2, 2): the largest of |d(u, v)/d mm| along them, px per mm."""
    p = np.asarray(point, np.float64)
    steps = [np.append(a, 0.0) * 0.5 for a in axes]
    uv = camera.project(np.vstack([p, p + steps[0], p + steps[1]]))
    return float(max(np.linalg.norm(uv[1] - uv[0]), np.linalg.norm(uv[2] - uv[0])) / 0.5)


def mark_frame(pattern: Pattern, margin_mm: float, px_mm: float) -> MarkFrame:
    """The frame of a placed ``pattern``: along its frame's edges (a code: the symbol with its
    quiet zone) or world x, y over its bounds (a drawing), ``margin_mm`` around it; px_mm
    raised so that the picture's longer side is at most :data:`MAX_PX`."""
    if pattern.frame is not None:
        f = pattern.frame
        u = (f[1] - f[0]) / np.linalg.norm(f[1] - f[0])
        v = np.array([-u[1], u[0]])
        size = (float(np.linalg.norm(f[1] - f[0])), float(np.linalg.norm(f[3] - f[0])))
        corner = f[0]
    else:
        x0, y0, x1, y1 = pattern.bounds()
        u, v = np.array([1.0, 0.0]), np.array([0.0, 1.0])
        size, corner = (x1 - x0, y1 - y0), np.array([x0, y0])
    size = (size[0] + 2 * margin_mm, size[1] + 2 * margin_mm)
    px = max(px_mm, max(size) / MAX_PX)
    return MarkFrame(corner - margin_mm * (u + v), np.vstack([u, v]), size, px)


def surface_points(frame: MarkFrame, surf: Surface, projection: Projection) -> np.ndarray:
    """(H, W, 3) world mm: the surface point each picture pixel shows as the job's
    ``projection`` put the pattern there (planar or wrap); NaN where the cloud does not show
    the surface (a hole, beside a step)."""
    xy = frame.pattern_xy().reshape(-1, 2)
    if projection.direction_deg is not None and projection.anchor is not None:
        xy = _unrolled_to_world(xy, surf, np.asarray(projection.anchor, np.float64),
                                math.radians(projection.direction_deg))
    # z on a grid about the cloud's spacing, bilinear in between (NaN spreads: masked)
    h, w = frame.shape
    k = max(1, int(surf.spacing_mm / frame.px_mm))
    coarse = xy.reshape(h, w, 2)[::k, ::k]
    s = surf.sample(coarse.reshape(-1, 2))
    zc = np.where(s.unmeasured, np.nan, s.z).reshape(coarse.shape[:2])
    rr, cc = np.meshgrid(np.arange(h) / k, np.arange(w) / k, indexing="ij")
    z = _bilinear_nan(zc, rr, cc)
    return np.dstack([xy.reshape(h, w, 2), z])


def _bilinear_nan(grid: np.ndarray, rr: np.ndarray, cc: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of ``grid`` at fractional (rows, cols); NaN when a corner is."""
    r0 = np.clip(np.floor(rr).astype(int), 0, grid.shape[0] - 1)
    c0 = np.clip(np.floor(cc).astype(int), 0, grid.shape[1] - 1)
    r1, c1 = np.minimum(r0 + 1, grid.shape[0] - 1), np.minimum(c0 + 1, grid.shape[1] - 1)
    fr, fc = np.clip(rr - r0, 0, 1), np.clip(cc - c0, 0, 1)
    return ((grid[r0, c0] * (1 - fc) + grid[r0, c1] * fc) * (1 - fr)
            + (grid[r1, c0] * (1 - fc) + grid[r1, c1] * fc) * fr)


def _unrolled_to_world(xy: np.ndarray, surf: Surface, anchor: np.ndarray,
                       theta_rad: float) -> np.ndarray:
    """Pattern-plane x, y (N, 2) → world x, y (N, 2) by the equal-arc-length map about
    ``anchor`` unrolled along ``theta_rad`` (as :func:`.project.project_wrap` maps)."""
    rel = xy - anchor
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    ab = rel @ np.array([[c, -s], [s, c]])
    radius = float(np.max(np.linalg.norm(rel, axis=1)))
    h = max(surf.spacing_mm, 2 * (radius + 1.0) / _MAX_GRID, _WRAP_GRID_MM)
    grad = _GradientGrid(surf, anchor, radius + 4 * h, h)
    amap = ArcLengthMap(grad, anchor, theta_rad, (ab[:, 0].min(), ab[:, 0].max()),
                        (ab[:, 1].min(), ab[:, 1].max()), h)
    return amap(ab)


def occluded(points: np.ndarray, camera_centre: np.ndarray, cloud_points: np.ndarray,
             cell_mm: float) -> np.ndarray:
    """(N,) bool: the measured surface stands between each point (N, 3) and the camera
    centre (3,): marching from the point toward the camera in ``cell_mm`` steps, a height map
    of ``cloud_points`` (M, 3) (highest point per cell) rises above the ray by more than
    0.2 mm. Non-finite points are not tested (False)."""
    out = np.zeros(len(points), bool)
    ok = np.isfinite(points).all(1)
    if not ok.any() or len(cloud_points) == 0:
        return out
    p = points[ok]
    d = camera_centre - p
    horiz = np.linalg.norm(d[:, :2], axis=1)
    rise = d[:, 2] / np.maximum(horiz, 1e-9)               # ray height per mm across
    unit = d[:, :2] / np.maximum(horiz, 1e-9)[:, None]
    ztop = float(cloud_points[:, 2].max())
    reach = np.clip((ztop - p[:, 2]) / np.maximum(rise, 1e-9), 0, None)   # past it: above all
    lo = np.minimum(p[:, :2].min(0), (p[:, :2] + unit * reach[:, None]).min(0)) - cell_mm
    hi = np.maximum(p[:, :2].max(0), (p[:, :2] + unit * reach[:, None]).max(0)) + cell_mm
    q = cloud_points[((cloud_points[:, :2] >= lo) & (cloud_points[:, :2] <= hi)).all(1)]
    shape = np.ceil((hi - lo) / cell_mm).astype(int) + 1
    hmap = np.full(shape[0] * shape[1], -np.inf)
    ij = ((q[:, :2] - lo) / cell_mm).astype(int)
    np.maximum.at(hmap, ij[:, 0] * shape[1] + ij[:, 1], q[:, 2])
    blocked = np.zeros(len(p), bool)
    for s in np.arange(3 * cell_mm, float(reach.max()) + cell_mm, cell_mm):
        live = ~blocked & (reach >= s - cell_mm)
        if not live.any():
            break
        at = p[live, :2] + unit[live] * s
        ij = np.clip(((at - lo) / cell_mm).astype(int), 0, shape - 1)
        ray_z = p[live, 2] + rise[live] * s
        blocked[np.flatnonzero(live)[hmap[ij[:, 0] * shape[1] + ij[:, 1]]
                                     > ray_z + _OCCLUSION_TOL_MM]] = True
    out[ok] = blocked
    return out


def rectify(image: np.ndarray, camera: CameraModel, points: np.ndarray,
            cloud_points: np.ndarray, cell_mm: float) -> np.ndarray:
    """(H, W) float32 picture: ``image`` (camera frame, (h, w) or (h, w, 3) → grey) sampled
    where each surface point (H, W, 3) mm projects (bilinear); NaN where the point is NaN,
    off the frame or hidden from the camera by the measured surface (:func:`occluded`)."""
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    img = img.astype(np.float32)
    h, w = points.shape[:2]
    flat = points.reshape(-1, 3)
    ok = np.isfinite(flat).all(1)
    uv = np.full((len(flat), 2), np.nan)
    uv[ok] = camera.project(flat[ok])
    ok &= np.isfinite(uv).all(1)
    ok[ok] = camera.in_image(uv[ok], margin=1.0)
    ok &= ~occluded(flat, camera.centre_world, cloud_points, cell_mm)
    maps = np.where(ok[:, None], uv, -10.0).astype(np.float32).reshape(h, w, 2)
    out = cv2.remap(img, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    out[~ok.reshape(h, w)] = np.nan
    return out
