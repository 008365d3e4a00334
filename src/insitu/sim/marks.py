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
from insitu.sim.render import NOMINAL_EXPOSURE_MS
from insitu.sim.rig import SimRig
from insitu.sim.scene import Scene

MARK_CONTRAST = 0.75      # a mark's centre reflects 25 % of the bare surface's light


@dataclass(frozen=True)
class Burn:
    """points: (N, 3) mm on the true surface (NaN rows where the beam missed every part);
    widths: (N,) mm, 1/e² diameter of the spot there; power_pct of the laser."""

    points: np.ndarray
    widths: np.ndarray
    power_pct: float = 0.0


def _burn_samples(burns: list[Burn]) -> tuple[np.ndarray, np.ndarray]:
    """Burn polylines resampled to ≤ a quarter of their width: (M, 3) points, (M,) radii."""
    pts, rad = [], []
    for b in burns:
        p, w = np.asarray(b.points, float), np.asarray(b.widths, float)
        ok = np.isfinite(p).all(1) & np.isfinite(w)
        for run in np.split(np.arange(len(p)), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1):
            if not ok[run[0]]:
                continue
            q, r = p[run], w[run] / 2
            pts.append(q[:1])
            rad.append(r[:1])
            if len(q) > 1:
                seg = np.linalg.norm(np.diff(q, axis=0), axis=1)
                n = np.maximum(np.ceil(seg / (0.25 * np.minimum(r[:-1], r[1:]))), 1).astype(int)
                for i in range(len(seg)):
                    t = (np.arange(1, n[i] + 1) / n[i])[:, None]
                    pts.append(q[i] + t * (q[i + 1] - q[i]))
                    rad.append(r[i] + t[:, 0] * (r[i + 1] - r[i]))
    if not pts:
        return np.zeros((0, 3)), np.zeros(0)
    return np.vstack(pts), np.concatenate(rad)


def mark_darkness(points: np.ndarray, burns: list[Burn],
                  contrast: float = MARK_CONTRAST) -> np.ndarray:
    """(N,) fraction of light a surface point (N, 3) loses to the burns: contrast ×
    exp(−2 d²/r²), d its distance to the nearest burn sample, r the spot radius there."""
    out = np.zeros(len(points))
    samples, radius = _burn_samples(burns)
    if len(samples) == 0 or len(points) == 0:
        return out
    tree = cKDTree(samples)
    k = min(8, len(samples))
    d, idx = tree.query(points, k=k, distance_upper_bound=2.0 * radius.max(), workers=-1)
    d, idx = d.reshape(len(points), k), idx.reshape(len(points), k)
    ok = np.isfinite(d)
    r = np.append(radius, 1.0)[idx]
    dark = np.where(ok, np.exp(-2 * (np.where(ok, d, 0) / r) ** 2), 0.0).max(1)
    return contrast * dark


def render_inspection(rig: SimRig, scene: Scene, burns: list[Burn],
                      exposure_ms: float = 12 * NOMINAL_EXPOSURE_MS, seed: int = 0,
                      ideal: bool = False, contrast: float = MARK_CONTRAST,
                      window: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """(H, W) frame of the true camera under room light, marks darker. One ray per pixel
    centre. ``ideal``: untextured, noise-free float32; else 8-bit with shot and read noise.
    ``window`` (row0, row1, col0, col1): only those pixels rendered (the rest dark, as if
    unlit), for speed."""
    cam, o = rig.camera, rig.optics
    H, W = cam.height, cam.width
    r0, r1, c0, c1 = window if window is not None else (0, H, 0, W)
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    lit = np.zeros((H, W), bool)
    lit[max(r0, 0):r1, max(c0, 0):c1] = True
    lit = lit.ravel()
    origin, dirs = cam.rays(np.column_stack([u.ravel()[lit], v.ravel()[lit]]))
    hits = scene.cast(np.broadcast_to(origin, dirs.shape), dirs)
    shade = np.zeros(int(lit.sum()))
    p, part, nrm = hits.points[hits.hit], hits.part[hits.hit], hits.normals[hits.hit]
    albedo = (np.array([scene.materials[i].albedo for i in part]) if ideal
              else scene.albedo(p, part))
    albedo = albedo * (1.0 - mark_darkness(p, burns, contrast))
    shade[hits.hit] = (o.ambient_dn * albedo * (0.6 + 0.4 * np.abs(nrm[:, 2]))
                       * exposure_ms / NOMINAL_EXPOSURE_MS)
    img = np.zeros(H * W, np.float32)
    img[lit] = shade
    img = img.reshape(H, W)
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
