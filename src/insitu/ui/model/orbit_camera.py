"""The 3-D view's camera as plain maths (no OpenGL): orbit about a centre, pan, zoom, preset
views, projection and picking rays. World frame = scan-head frame, mm, z up."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

VIEWS = {"top": (-90.0, 90.0), "front": (-90.0, 0.0), "side": (0.0, 0.0),
         "iso": (-60.0, 35.0)}


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


@dataclass
class OrbitCamera:
    """A perspective camera looking at ``centre`` (mm, world) from ``distance_mm``, placed by
    ``azimuth_deg`` (about +z, from +x) and ``elevation_deg`` (above the xy plane; 90 looks
    straight down). ``fov_deg``: vertical field of view."""

    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance_mm: float = 300.0
    azimuth_deg: float = -60.0
    elevation_deg: float = 35.0
    fov_deg: float = 35.0

    # -- pose ------------------------------------------------------------------------------
    def eye(self) -> np.ndarray:
        """(3,) camera position, mm."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        d = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        return np.asarray(self.centre, float) + self.distance_mm * d

    def _up(self) -> np.ndarray:
        """World up for lookAt; straight down it is +y (screen up = +y in the top view)."""
        if abs(self.elevation_deg) > 89.0:
            az = math.radians(self.azimuth_deg)
            return np.array([-math.cos(az), -math.sin(az), 0.0]) * np.sign(self.elevation_deg)
        return np.array([0.0, 0.0, 1.0])

    def view_matrix(self) -> np.ndarray:
        """(4, 4) float64: world → eye coordinates (OpenGL: camera looks down −z)."""
        eye = self.eye()
        f = _normalize(np.asarray(self.centre, float) - eye)
        s = _normalize(np.cross(f, self._up()))
        u = np.cross(s, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ eye
        return m

    def projection_matrix(self, aspect: float) -> np.ndarray:
        """(4, 4) float64 perspective; near and far planes follow the distance."""
        near, far = self.distance_mm / 100.0, self.distance_mm * 20.0
        f = 1.0 / math.tan(math.radians(self.fov_deg) / 2)
        m = np.zeros((4, 4))
        m[0, 0], m[1, 1] = f / max(aspect, 1e-6), f
        m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
        m[3, 2] = -1.0
        return m

    def mvp(self, aspect: float) -> np.ndarray:
        """(4, 4) float32 world → clip, row-major (upload transposed)."""
        return (self.projection_matrix(aspect) @ self.view_matrix()).astype(np.float32)

    # -- interaction -----------------------------------------------------------------------
    def orbit(self, d_azimuth_deg: float, d_elevation_deg: float) -> None:
        self.azimuth_deg = (self.azimuth_deg + d_azimuth_deg) % 360.0
        self.elevation_deg = float(np.clip(self.elevation_deg + d_elevation_deg, -90.0, 90.0))

    def pan(self, dx_px: float, dy_px: float, height_px: int) -> None:
        """Move the centre with the mouse: (dx, dy) pixels, screen right and down."""
        mm_per_px = 2 * self.distance_mm * math.tan(math.radians(self.fov_deg) / 2) / height_px
        v = self.view_matrix()
        right, up = v[0, :3], v[1, :3]
        self.centre = np.asarray(self.centre, float) + mm_per_px * (-dx_px * right + dy_px * up)

    def zoom(self, factor: float) -> None:
        """Distance times ``factor`` (< 1 zooms in), kept within 1 mm … 10 m."""
        self.distance_mm = float(np.clip(self.distance_mm * factor, 1.0, 1e4))

    def set_view(self, name: str) -> None:
        """One of :data:`VIEWS`: top, front (looking along +y), side (along −x), iso."""
        self.azimuth_deg, self.elevation_deg = VIEWS[name]

    def frame(self, lo, hi) -> None:
        """Centre on the box (lo, hi) mm and back off until it fits the view."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        self.centre = (lo + hi) / 2
        radius = max(float(np.linalg.norm(hi - lo)) / 2, 1.0)
        self.distance_mm = radius / math.sin(math.radians(self.fov_deg) / 2) * 1.1

    # -- picking ---------------------------------------------------------------------------
    def project(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """(N, 3) world mm → (N, 2) widget pixels (x right, y down); NaN behind the camera."""
        p = np.c_[np.asarray(points, float).reshape(-1, 3), np.ones(len(points))]
        clip = p @ (self.projection_matrix(width / height) @ self.view_matrix()).T
        w = np.where(clip[:, 3] > 1e-9, clip[:, 3], np.nan)
        ndc = clip[:, :2] / w[:, None]
        return np.c_[(ndc[:, 0] + 1) * width / 2, (1 - ndc[:, 1]) * height / 2]

    def ray(self, x_px: float, y_px: float, width: int, height: int
            ) -> tuple[np.ndarray, np.ndarray]:
        """The world ray under a widget pixel: origin (3,) at the eye, unit direction (3,)."""
        ndc = np.array([2 * x_px / width - 1, 1 - 2 * y_px / height, 1.0, 1.0])
        inv = np.linalg.inv(self.projection_matrix(width / height) @ self.view_matrix())
        far = inv @ ndc
        eye = self.eye()
        return eye, _normalize(far[:3] / far[3] - eye)

    def pick_plane(self, x_px: float, y_px: float, width: int, height: int,
                   z_mm: float = 0.0) -> np.ndarray | None:
        """(3,) where the ray under the pixel meets the plane z = ``z_mm``; None if it
        doesn't (parallel, or behind the camera)."""
        o, d = self.ray(x_px, y_px, width, height)
        if abs(d[2]) < 1e-9:
            return None
        t = (z_mm - o[2]) / d[2]
        return o + t * d if t > 0 else None
