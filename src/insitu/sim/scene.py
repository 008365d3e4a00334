"""The simulated rig's world: workpieces on the table, ray-cast with Open3D, with materials.

Rays are cast in float32 by Open3D; origins are moved close to the surface first so that hit
points keep ~1e-5 mm precision.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from insitu.sim.workpieces import Workpiece


@dataclass(frozen=True)
class Material:
    """Diffuse albedo (0..1), specular fraction and Phong exponent, texture amplitude (0..1);
    along-line speckle: coefficient of variation and correlation length on the surface, mm;
    mirror: the fraction of light a face reflects as a (slightly blurred) mirror image.
    Values and their sources: docs/simulator.md."""

    albedo: float = 0.5
    specular: float = 0.2
    shininess: float = 40.0
    texture: float = 0.15
    speckle_cv: float = 0.25
    speckle_corr_mm: float = 0.25
    mirror: float = 0.0


_MATTE = dict(speckle_cv=0.25, speckle_corr_mm=0.25)
_METAL = dict(speckle_cv=0.45, speckle_corr_mm=0.25)
MATERIALS = {
    "table": Material(albedo=0.12, specular=0.05, shininess=10.0, texture=0.10, **_MATTE),
    "plate": Material(albedo=0.60, specular=0.05, shininess=10.0, texture=0.04, **_MATTE),
    "step-block": Material(albedo=0.45, specular=0.30, shininess=60.0, texture=0.15, mirror=0.50,
                           **_METAL),
    "arc": Material(albedo=0.50, specular=0.40, shininess=80.0, texture=0.12, mirror=0.50,
                    **_METAL),
    "insert": Material(albedo=0.25, specular=0.45, shininess=120.0, texture=0.08, mirror=0.55,
                       **_METAL),
    # the engraving blanks (sim/ablation.py holds how each ablates)
    "blank-stainless": Material(albedo=0.45, specular=0.35, shininess=60.0, texture=0.10,
                                mirror=0.35, **_METAL),
    "blank-anodised": Material(albedo=0.35, specular=0.15, shininess=20.0, texture=0.06,
                               mirror=0.10, speckle_cv=0.30, speckle_corr_mm=0.25),
    "blank-beech": Material(albedo=0.55, specular=0.05, shininess=8.0, texture=0.20, **_MATTE),
}
DEFAULT_MATERIAL = Material(mirror=0.45, **_METAL)  # machined parts without an entry


@dataclass
class Hits:
    """Result of a ray cast. All (N, ...) arrays; ``hit`` (N,) bool; ids index ``Scene.parts``."""

    hit: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    part: np.ndarray


class Scene:
    """Workpieces (the first is usually the table) in one Open3D RaycastingScene."""

    def __init__(self, parts: list[Workpiece], seed: int = 0,
                 materials: dict[str, Material] | None = None):
        """``materials``: a part's material by name, in place of :data:`MATERIALS`' (another
        finish: its texture, its albedo against the table's)."""
        self.parts = list(parts)
        self._scene = o3d.t.geometry.RaycastingScene()
        self._ids = [self._scene.add_triangles(p.o3d_tensor_mesh()) for p in self.parts]
        self._id_to_part = np.full(max(self._ids) + 2, -1, dtype=np.int64)
        self._id_to_part[np.array(self._ids)] = np.arange(len(self._ids))
        chosen = {**MATERIALS, **(materials or {})}
        self.materials = [chosen.get(p.name, DEFAULT_MATERIAL) for p in self.parts]
        rng = np.random.default_rng(seed)
        # Surface texture: a few random plane waves per part (wavelengths 0.4–25 mm).
        self._waves = [
            (rng.normal(size=(6, 3)) * (2 * np.pi / rng.uniform(0.4, 25.0, 6))[:, None],
             rng.uniform(0, 2 * np.pi, 6), rng.uniform(0.3, 1.0, 6))
            for _ in self.parts
        ]

    def cast(self, origins: np.ndarray, dirs: np.ndarray, max_t: float = np.inf,
             lift_to_z: float | None = 60.0) -> Hits:
        """First hit along each ray (N, 3) origins, (N, 3) unit dirs. ``lift_to_z``: start
        downward rays at this height (precision); rays must not start inside a part."""
        origins = np.asarray(origins, np.float64)
        dirs = np.asarray(dirs, np.float64)
        offset = np.zeros(len(origins))
        if lift_to_z is not None:
            down = dirs[:, 2] < -1e-9
            s = np.where(down, (origins[:, 2] - lift_to_z) / -np.where(down, dirs[:, 2], -1), 0.0)
            offset = np.maximum(s, 0.0)
        start = origins + offset[:, None] * dirs
        rays = o3d.core.Tensor(np.hstack([start, dirs]).astype(np.float32))
        ans = self._scene.cast_rays(rays)
        t = ans["t_hit"].numpy().astype(np.float64)
        hit = np.isfinite(t) & (t + offset < max_t)
        t = np.where(hit, t, 0.0)
        points = start + t[:, None] * dirs
        normals = ans["primitive_normals"].numpy().astype(np.float64)
        gid = ans["geometry_ids"].numpy().astype(np.int64)
        part = np.where(hit, self._id_to_part[np.clip(gid, 0, len(self._id_to_part) - 1)], -1)
        # face normals toward the incoming ray
        flip = np.sum(normals * dirs, axis=1) > 0
        normals[flip] *= -1
        return Hits(hit, points, normals, part)

    def visible_from(self, points: np.ndarray, normals: np.ndarray, eye: np.ndarray) -> np.ndarray:
        """(N,) bool: the point faces ``eye`` (3,) and nothing lies between (occlusion)."""
        to_eye = np.asarray(eye, float) - points
        dist = np.linalg.norm(to_eye, axis=1)
        d = to_eye / dist[:, None]
        facing = np.sum(d * normals, axis=1) > 1e-3
        start = points + 1e-3 * normals
        rays = o3d.core.Tensor(np.hstack([start, d]).astype(np.float32))
        t = self._scene.cast_rays(rays)["t_hit"].numpy()
        return facing & ~(t < dist - 1e-2)

    def albedo(self, points: np.ndarray, part: np.ndarray) -> np.ndarray:
        """(N,) diffuse reflectance at world points of the given parts (textured)."""
        out = np.zeros(len(points))
        for i, mat in enumerate(self.materials):
            sel = part == i
            if not sel.any():
                continue
            k, phase, amp = self._waves[i]
            tex = (np.sin(points[sel] @ k.T + phase) * amp).sum(1) / amp.sum()
            out[sel] = mat.albedo * (1.0 + mat.texture * tex)
        return out

    def material_arrays(self, part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) specular fraction and shininess for each hit's part."""
        return self.material_field(part, "specular", 0.0), self.material_field(part, "shininess", 1.0)

    def material_field(self, part: np.ndarray, name: str, missed: float = 0.0) -> np.ndarray:
        """(N,) the material attribute ``name`` of each hit's part (``missed`` for part −1)."""
        return np.array([getattr(m, name) for m in self.materials] + [missed])[part]
