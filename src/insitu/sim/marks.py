"""Laser marks burnt into the simulated workpiece, and the camera's view of the marked part.

A :class:`Burn` is a 3-D polyline on the true surface with a width per point (the 1/e² beam
diameter where it met the surface, growing out of focus). :func:`render_inspection` renders
the true camera's frame of the scene under room light with every burn darkening the surface
albedo along its path (Gaussian profile across the mark). :func:`find_marks` is the
inspection side: dark thin features in a frame, back-projected through the operator's camera
onto a known plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree

from insitu.geometry.camera import CameraModel
from insitu.sim.render import NOMINAL_EXPOSURE_MS, lens_blur_px
from insitu.sim.rig import SimRig
from insitu.sim.room_light import area_rays, edge_pixels, room_shade
from insitu.sim.scene import Scene

MARK_CONTRAST = 0.75      # a mark's centre reflects 25 % of the bare surface's light


@dataclass(frozen=True)
class Burn:
    """points: (N, 3) mm on the true surface (NaN rows where the beam missed every part);
    widths: (N,) mm, 1/e² diameter of the spot there; power_pct of the laser; ``passes``:
    how many times the beam went this way (each pass darkens what the last one left)."""

    points: np.ndarray
    widths: np.ndarray
    power_pct: float = 0.0
    passes: int = 1

    def again(self, other: "Burn") -> bool:
        """Whether ``other`` is another pass along this burn (same samples)."""
        return (self.points.shape == other.points.shape
                and np.array_equal(self.points, other.points, equal_nan=True))


def _burn_samples(burns: list[Burn]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Burn polylines resampled to ≤ a quarter of their width: (M, 3) points, (M,) radii,
    (M,) passes."""
    pts, rad, passes = [], [], []
    for b in burns:
        p, w = np.asarray(b.points, float), np.asarray(b.widths, float)
        ok = np.isfinite(p).all(1) & np.isfinite(w)
        for run in np.split(np.arange(len(p)), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1):
            if not ok[run[0]]:
                continue
            q, r = p[run], w[run] / 2
            seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
            n = np.maximum(np.ceil(seg / (0.25 * np.minimum(r[:-1], r[1:]))), 1).astype(int)
            i = np.repeat(np.arange(len(seg)), n)             # each new sample's segment
            t = (np.arange(len(i)) - np.repeat(np.cumsum(n) - n, n) + 1) / n[i]
            pts += [q[:1], q[i] + t[:, None] * (q[i + 1] - q[i])]
            rad += [r[:1], r[i] + t * (r[i + 1] - r[i])]
            passes.append(np.full(1 + len(i), b.passes))
    if not pts:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0)
    return np.vstack(pts), np.concatenate(rad), np.concatenate(passes)


def mark_darkness(points: np.ndarray, burns: list[Burn],
                  contrast: float = MARK_CONTRAST) -> np.ndarray:
    """(N,) fraction of light a surface point (N, 3) loses to the burns: c × exp(−2 d²/r²),
    d its distance to the nearest burn sample, r the spot radius there, c = 1 − (1 −
    contrast)^passes (each pass darkens what the last one left)."""
    out = np.zeros(len(points))
    samples, radius, passes = _burn_samples(burns)
    if len(samples) == 0 or len(points) == 0:
        return out
    tree = cKDTree(samples)
    k = min(8, len(samples))
    d, idx = tree.query(points, k=k, distance_upper_bound=2.0 * radius.max(), workers=-1)
    d, idx = d.reshape(len(points), k), idx.reshape(len(points), k)
    ok = np.isfinite(d)
    r = np.append(radius, 1.0)[idx]
    c = 1.0 - (1.0 - contrast) ** np.append(passes, 1.0)[idx]
    return np.where(ok, c * np.exp(-2 * (np.where(ok, d, 0) / r) ** 2), 0.0).max(1)


class RoomLightView:
    """What the true camera of ``rig`` sees of ``scene`` under room light, cast once: one ray
    per pixel centre, and in the pixels an edge crosses (:func:`~insitu.sim.render.
    edge_pixels`) ``EDGE_SUB``² rays over the pixel's area. ``hit`` (H·W,) bool, ``points``
    (M, 3) float32 mm where the hit pixels' centres meet, ``shade`` (M,) float32 DN at the
    nominal exposure (albedo, textured unless ``ideal``, shaded by the normal; an edge's
    pixels their area's mean), ``blur_px``: the lens PSF's σ at the scene's depth."""

    def __init__(self, rig: SimRig, scene: Scene, ideal: bool = False, rows: int = 256):
        cam = rig.camera
        H, W = self.shape = (cam.height, cam.width)
        hit, points, shade, keys = [], [], [], []
        for v0 in range(0, H, rows):                 # a block of rows at a time: flat memory
            u, v = np.meshgrid(np.arange(W, dtype=np.float64),
                               np.arange(v0, min(v0 + rows, H), dtype=np.float64))
            hits, s = self._cast(rig, scene, np.column_stack([u.ravel(), v.ravel()]), ideal)
            key = np.full((len(s), 3), -1.0, np.float32)   # part, |n_z|, depth
            p = hits.points[hits.hit]
            key[hits.hit] = np.column_stack([hits.part[hits.hit],
                                             np.abs(hits.normals[hits.hit, 2]),
                                             cam.to_camera(p)[:, 2]])
            hit.append(hits.hit)
            points.append(p.astype(np.float32))
            shade.append(s[hits.hit])
            keys.append(key)
        self.hit, self.points, self.shade = (np.concatenate(a) for a in (hit, points, shade))
        key = np.concatenate(keys).reshape(H, W, 3)
        rows_, cols = np.nonzero(edge_pixels(key[..., 0], key[..., 1], key[..., 2])
                                 & self.hit.reshape(H, W))
        if len(rows_):
            area = self._cast(rig, scene, area_rays(rows_, cols), ideal)[1]
            index = np.cumsum(self.hit) - 1                  # pixel → its row in shade
            self.shade[index[rows_ * W + cols]] = area.reshape(len(rows_), -1).mean(1)
        seen = key[..., 0] >= 0
        self.blur_px = float(lens_blur_px(rig, np.median(key[..., 2][seen]))) if seen.any() \
            else 0.0

    @staticmethod
    def _cast(rig: SimRig, scene: Scene, uv: np.ndarray, ideal: bool):
        """The hits of the true camera's rays through pixels ``uv`` (N, 2) and their room
        light (N,) float32 DN at the nominal exposure (0 where nothing is met)."""
        origin, dirs = rig.camera.rays(uv)
        hits = scene.cast(np.broadcast_to(origin, dirs.shape), dirs)
        p, part = hits.points[hits.hit], hits.part[hits.hit]
        albedo = (np.array([scene.materials[i].albedo for i in part]) if ideal
                  else scene.albedo(p, part))
        shade = np.zeros(len(uv), np.float32)
        shade[hits.hit] = room_shade(rig, scene, hits, albedo)
        return hits, shade


def render_inspection(rig: SimRig, scene: Scene, burns: list[Burn],
                      exposure_ms: float = 12 * NOMINAL_EXPOSURE_MS, seed: int = 0,
                      ideal: bool = False, contrast: float = MARK_CONTRAST,
                      view: RoomLightView | None = None) -> np.ndarray:
    """(H, W) frame of the true camera under room light, marks darker, through the lens PSF
    (``view``: the scene's :class:`RoomLightView`, made for the same rig, scene and
    ``ideal``, kept by the caller). ``ideal``: untextured, noise-free float32; else 8-bit with
    shot and read noise."""
    o = rig.optics
    view = view or RoomLightView(rig, scene, ideal)
    H, W = view.shape
    shade = view.shade.copy()
    samples, radius, _ = _burn_samples(burns)
    if len(samples):              # only the pixels near a burn can be darker
        reach = 2.0 * float(radius.max()) + 1e-3
        near = ((view.points >= samples.min(0) - reach)
                & (view.points <= samples.max(0) + reach)).all(1)
        shade[near] *= (1.0 - mark_darkness(view.points[near].astype(np.float64), burns,
                                            contrast)).astype(np.float32)
    img = np.zeros(H * W, np.float32)
    img[view.hit] = shade * np.float32(exposure_ms / NOMINAL_EXPOSURE_MS)
    img = img.reshape(H, W)
    if view.blur_px > 0.05:
        img = cv2.GaussianBlur(img, (0, 0), view.blur_px)
    if ideal:
        return img
    rng = np.random.default_rng(seed)
    img += np.float32(o.dark_dn)
    var = img / np.float32(o.electrons_per_dn) + np.float32(o.read_noise_dn ** 2)
    img += rng.standard_normal((H, W), dtype=np.float32) * np.sqrt(var)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def find_marks(image: np.ndarray, camera: CameraModel, plane_z: float,
               min_contrast: float = 0.3, kernel_px: int = 15
               ) -> tuple[np.ndarray, np.ndarray]:
    """Where marks are on the plane z = ``plane_z`` (mm): pixels at least ``min_contrast``
    darker than their surroundings (background by a grey closing ``kernel_px`` wide, wider
    than a mark), back-projected through ``camera``. Returns (M, 2) world x, y, mm and (M,)
    contrast weights."""
    img = np.asarray(image, np.float32)
    img = cv2.GaussianBlur(img, (3, 3), 0.7)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (kernel_px, kernel_px))
    bg = cv2.morphologyEx(img, cv2.MORPH_CLOSE, kernel)
    c = 1.0 - img / np.maximum(bg, 1.0)
    vv, uu = np.nonzero((c > min_contrast) & (bg > 8.0))
    if len(uu) == 0:
        return np.zeros((0, 2)), np.zeros(0)
    origin, d = camera.rays(np.column_stack([uu, vv]).astype(np.float64))
    t = (plane_z - origin[2]) / d[:, 2]
    xy = origin[:2] + t[:, None] * d[:, :2]
    return xy, c[vv, uu].astype(np.float64)


def burnt_centre(burns: list[Burn], T_world_part: np.ndarray) -> np.ndarray | None:
    """Centre (2,) mm of the bounding box of every burnt point, in the frame of the part
    that ``T_world_part`` (4, 4) places — the simulator's truth of where a pattern was marked
    on the part (None: nothing burnt)."""
    pts = [b.points[np.isfinite(b.points).all(1)] for b in burns]
    pts = [p for p in pts if len(p)]
    if not pts:
        return None
    inv = np.linalg.inv(np.asarray(T_world_part, float))
    part = np.vstack(pts) @ inv[:3, :3].T + inv[:3, 3]
    return (part[:, :2].min(0) + part[:, :2].max(0)) / 2
