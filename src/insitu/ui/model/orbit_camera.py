"""The 3-D view's camera as plain maths (no OpenGL): orbit about a centre, pan, zoom, preset
views, perspective or orthographic projection, framing and picking rays. World frame =
scan-head frame, mm, z up."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

VIEWS = {"top": (-90.0, 90.0), "front": (-90.0, 0.0), "side": (0.0, 0.0),
         "iso": (-60.0, 35.0)}
ORTHO_VIEWS = {"top"}            # placing: orthographic; looking: perspective
ORTHO_DEPTH_MM = 2000.0          # the orthographic view's depth range about the centre
FRAME_MARGIN = 0.9               # a framed box fills at most this share of the view


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


@dataclass
class OrbitCamera:
    """A camera looking at ``centre`` (mm, world) from ``distance_mm``, placed by
    ``azimuth_deg`` (about +z, from +x) and ``elevation_deg`` (above the xy plane; 90 looks
    straight down). ``fov_deg``: vertical field of view. ``ortho``: orthographic, showing
    the same height of the scene as the perspective view shows at ``centre``
    (2 · distance · tan(fov / 2) mm), so a toggle keeps the scale and zoom works alike."""

    centre: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance_mm: float = 300.0
    azimuth_deg: float = -60.0
    elevation_deg: float = 35.0
    fov_deg: float = 35.0
    ortho: bool = False

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

    def half_height_mm(self) -> float:
        """Half the height of the view at ``centre``, mm (the orthographic view's everywhere)."""
        return self.distance_mm * math.tan(math.radians(self.fov_deg) / 2)

    def mm_per_px(self, height_px: int) -> float:
        """Scale at ``centre``'s depth (everywhere in the orthographic view), mm per pixel."""
        return 2 * self.half_height_mm() / max(height_px, 1)

    def projection_matrix(self, aspect: float) -> np.ndarray:
        """(4, 4) float64 perspective or orthographic; near and far planes follow the
        distance (orthographic: ±:data:`ORTHO_DEPTH_MM` about the centre)."""
        m = np.zeros((4, 4))
        if self.ortho:
            near, far = self.distance_mm - ORTHO_DEPTH_MM, self.distance_mm + ORTHO_DEPTH_MM
            h = self.half_height_mm()
            m[0, 0], m[1, 1] = 1 / (h * max(aspect, 1e-6)), 1 / h
            m[2, 2], m[2, 3] = -2 / (far - near), -(far + near) / (far - near)
            m[3, 3] = 1.0
            return m
        near, far = self.distance_mm / 100.0, self.distance_mm * 20.0
        f = 1.0 / math.tan(math.radians(self.fov_deg) / 2)
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
        mm_per_px = self.mm_per_px(height_px)
        v = self.view_matrix()
        right, up = v[0, :3], v[1, :3]
        self.centre = np.asarray(self.centre, float) + mm_per_px * (-dx_px * right + dy_px * up)

    def zoom(self, factor: float) -> None:
        """Distance times ``factor`` (< 1 zooms in), kept within 1 mm … 10 m."""
        self.distance_mm = float(np.clip(self.distance_mm * factor, 1.0, 1e4))

    def set_view(self, name: str) -> None:
        """One of :data:`VIEWS`: top (orthographic), front (looking along +y), side (along
        −x), iso (perspective)."""
        self.azimuth_deg, self.elevation_deg = VIEWS[name]
        self.ortho = name in ORTHO_VIEWS

    def frame(self, lo, hi, aspect: float = 1.0, reserve: float = 0.0) -> None:
        """Centre on the box (lo, hi) mm and set the distance so that its eight corners
        fill at most :data:`FRAME_MARGIN` of a view of width / height ``aspect``, less the
        fraction ``reserve`` of its width on the right (where the colour bar is)."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        self.centre = (lo + hi) / 2
        full_aspect, aspect = aspect, aspect * (1.0 - reserve)
        v = self.view_matrix()
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])]) - self.centre
        s, u, back = corners @ v[0, :3], corners @ v[1, :3], corners @ v[2, :3]
        tan_v = math.tan(math.radians(self.fov_deg) / 2)
        tan_h = tan_v * aspect
        if self.ortho:
            h = max(float(np.abs(u).max()), float(np.abs(s).max()) / aspect, 0.5) / FRAME_MARGIN
            self.distance_mm = h / tan_v
        else:   # a corner at depth (d − back) must satisfy |s| ≤ m · tan_h · (d − back)
            need = np.maximum(np.abs(s) / tan_h, np.abs(u) / tan_v) / FRAME_MARGIN + back
            self.distance_mm = max(float(need.max()), 1.0)
        self.distance_mm = float(np.clip(self.distance_mm, 1.0, 1e4))
        if reserve > 0:
            self._beside_band(s, back, tan_v * full_aspect, reserve, v[0, :3])

    def _beside_band(self, s, back, tan_h: float, reserve: float, right) -> None:
        """Move the view right by the reserved band's half width at the centre's depth, so
        the box (corners at ``s`` across, ``back`` towards the eye, mm) lies left of the
        band; a perspective view steps back until its nearest corners fit too."""
        for _ in range(40):
            half = self.distance_mm * tan_h                      # half the view's width, mm
            shift = reserve * half
            depth = np.ones_like(back) if self.ortho else 1 - back / self.distance_mm
            x = (s - shift) / (half * depth)                     # −1 … 1 across the view
            if self.ortho or (x.min() >= -1 and x.max() <= 1 - 2 * reserve) \
                    or self.distance_mm >= 1e4:
                break
            self.distance_mm = min(self.distance_mm * 1.05, 1e4)
        self.centre = self.centre + shift * np.asarray(right)

    # -- picking ---------------------------------------------------------------------------
    def project(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """(N, 3) world mm → (N, 2) widget pixels (x right, y down); NaN behind the camera."""
        p = np.c_[np.asarray(points, float).reshape(-1, 3), np.ones(len(points))]
        clip = p @ (self.projection_matrix(width / height) @ self.view_matrix()).T
        w = np.where(clip[:, 3] > 1e-9, clip[:, 3], np.nan)
        ndc = clip[:, :2] / w[:, None]
        return np.c_[(ndc[:, 0] + 1) * width / 2, (1 - ndc[:, 1]) * height / 2]

    def rays(self, px: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """The world rays under (N, 2) widget pixels: origins (N, 3) on the near plane (the
        eye's, perspective; parallel rays, orthographic) and unit directions (N, 3)."""
        px = np.asarray(px, float).reshape(-1, 2)
        x, y = 2 * px[:, 0] / width - 1, 1 - 2 * px[:, 1] / height
        inv = np.linalg.inv(self.projection_matrix(width / height) @ self.view_matrix())
        ends = [np.c_[x, y, np.full(len(x), z), np.ones(len(x))] @ inv.T for z in (-1.0, 1.0)]
        near, far = (e[:, :3] / e[:, 3:] for e in ends)
        d = far - near
        return near, d / np.linalg.norm(d, axis=1, keepdims=True)

    def ray(self, x_px: float, y_px: float, width: int, height: int
            ) -> tuple[np.ndarray, np.ndarray]:
        """The world ray under a widget pixel: origin (3,), unit direction (3,)."""
        o, d = self.rays(np.array([[x_px, y_px]]), width, height)
        return o[0], d[0]

    def pick_planes(self, px: np.ndarray, width: int, height: int, z_mm: float = 0.0
                    ) -> np.ndarray:
        """(N, 3) where the rays under (N, 2) pixels meet the plane z = ``z_mm``; NaN rows
        where they don't (parallel, or behind the camera)."""
        o, d = self.rays(px, width, height)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(np.abs(d[:, 2]) > 1e-9, (z_mm - o[:, 2]) / d[:, 2], np.nan)
        t = np.where(t > 0, t, np.nan)
        return o + t[:, None] * d

    def pick_plane(self, x_px: float, y_px: float, width: int, height: int,
                   z_mm: float = 0.0) -> np.ndarray | None:
        """(3,) where the ray under the pixel meets the plane z = ``z_mm``; None if it
        doesn't (parallel, or behind the camera)."""
        p = self.pick_planes(np.array([[x_px, y_px]]), width, height, z_mm)[0]
        return None if np.isnan(p).any() else p
