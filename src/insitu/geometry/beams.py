"""Beam models of the scan head: a command (x, y) on z = 0 → the 3-D ray the laser travels.

* :class:`PivotHead` — Li et al. §2.1: every ray of a non-telecentric head passes through the
  pivot a = (0, 0, H); a telecentric head's rays are vertical.
* :class:`TwoMirrorHead` — Mikkelstrup et al. §2.3, Eqs. 1–5: mirror distance d, mirror
  separation e; forward and inverse kinematics, mirror angles and focus shift.
* :class:`ScanHeadOptics` — a beam model plus a field distortion that shifts where the beam
  lands on z = 0 (what a field correction has to undo).

Rays: origins (N, 3) and unit directions (N, 3) pointing down (dz < 0), world frame, mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from insitu.geometry.distortion import FieldDistortion, NoDistortion


class BeamModel(Protocol):
    def rays(self, cmd_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) commands on z = 0, mm → origins (N, 3), unit directions (N, 3)."""
        ...


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class PivotHead:
    """Li et al.'s model. ``pivot_height_mm``: H of the pivot a = (0, 0, H)."""

    pivot_height_mm: float
    telecentric: bool = False

    def rays(self, cmd_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cmd = np.asarray(cmd_xy, dtype=np.float64).reshape(-1, 2)
        n, H = len(cmd), self.pivot_height_mm
        if self.telecentric:
            origins = np.column_stack([cmd, np.full(n, H)])
            return origins, np.tile([0.0, 0.0, -1.0], (n, 1))
        origins = np.tile([0.0, 0.0, H], (n, 1))
        return origins, _unit(np.column_stack([cmd, np.full(n, -H)]))


@dataclass(frozen=True)
class TwoMirrorHead:
    """Mikkelstrup et al.'s two-mirror model (Eqs. 1–5).

    ``mirror_distance_mm`` d: from the last (x-deflecting) mirror axis to z = 0.
    ``mirror_separation_mm`` e: between the two mirror axes.
    Optical angles theta = 2 × mechanical angles alpha, radians.
    """

    mirror_distance_mm: float
    mirror_separation_mm: float

    @classmethod
    def of(cls, geometry) -> "TwoMirrorHead":
        """The nominal kinematics of a scan head's geometry (anything with
        ``mirror_distance_mm`` and ``mirror_separation_mm``, e.g.
        :class:`insitu.formats.rig.ScanHeadGeometry`)."""
        return cls(geometry.mirror_distance_mm, geometry.mirror_separation_mm)

    def forward(self, theta_x: np.ndarray, theta_y: np.ndarray, z: np.ndarray | float = 0.0
                ) -> tuple[np.ndarray, np.ndarray]:
        """Eqs. 1–2: optical angles, height z → (x, y) where the beam crosses height z, mm."""
        d, e = self.mirror_distance_mm, self.mirror_separation_mm
        x = (d - z) * np.tan(theta_x)
        y = (e + (d - z) / np.cos(theta_x)) * np.tan(theta_y)
        return x, y

    def inverse(self, x: np.ndarray, y: np.ndarray, z: np.ndarray | float = 0.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eqs. 3–5: target (x, y, z), mm → mechanical angles alpha_x, alpha_y (rad), and the
        DFM displacement Δf_r (mm) exactly as Eq. 5 defines it (relative to the centre of the
        plane at the same height z)."""
        d, e = self.mirror_distance_mm, self.mirror_separation_mm
        x, y = np.asarray(x, float), np.asarray(y, float)
        r = np.sqrt((d - z) ** 2 + x**2)
        alpha_x = 0.5 * np.arctan(x / (d - z))
        alpha_y = 0.5 * np.arctan(y / (e + r))
        dfr = np.sqrt((e + r) ** 2 + y**2) - (e + (d - z))
        return alpha_x, alpha_y, dfr

    def focus_shift(self, x: np.ndarray, y: np.ndarray, z: np.ndarray | float = 0.0) -> np.ndarray:
        """Change of beam path length to focus on (x, y, z), relative to focus on (0, 0, 0), mm:
        Eq. 5 minus z (Eq. 5 alone leaves out the shift between planes)."""
        return self.inverse(x, y, z)[2] - np.asarray(z, float)

    def rays_from_angles(self, theta_x: np.ndarray, theta_y: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Optical angles (N,) → rays. Origin on the last mirror axis (z = d)."""
        d, e = self.mirror_distance_mm, self.mirror_separation_mm
        tx, ty = np.tan(theta_x), np.tan(theta_y)
        origins = np.column_stack([np.zeros_like(tx), e * ty, np.full_like(tx, d)])
        dirs = _unit(np.column_stack([tx, ty / np.cos(theta_x), -np.ones_like(tx)]))
        return origins, dirs

    def rays(self, cmd_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cmd = np.asarray(cmd_xy, dtype=np.float64).reshape(-1, 2)
        ax, ay, _ = self.inverse(cmd[:, 0], cmd[:, 1], 0.0)
        return self.rays_from_angles(2 * ax, 2 * ay)


@dataclass(frozen=True)
class ScanHeadOptics:
    """A beam model whose landing point on z = 0 is shifted by a field distortion."""

    beam: BeamModel
    distortion: FieldDistortion = NoDistortion()

    def landing(self, cmd_xy: np.ndarray) -> np.ndarray:
        """(N, 2) commands → (N, 2) where the beam really meets z = 0, mm."""
        cmd = np.asarray(cmd_xy, dtype=np.float64).reshape(-1, 2)
        return cmd + self.distortion(cmd)

    def rays(self, cmd_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.beam.rays(self.landing(cmd_xy))


def line_commands(start: np.ndarray, end: np.ndarray, n: int) -> np.ndarray:
    """(n, 2) commands evenly spaced from ``start`` to ``end`` (both included), mm."""
    s = np.linspace(0.0, 1.0, n)[:, None]
    return (1 - s) * np.asarray(start, float) + s * np.asarray(end, float)


def line_sheet(beam: BeamModel, start: np.ndarray, end: np.ndarray, n: int
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sheet of rays that draws the line start → end: commands (n, 2), origins, dirs."""
    cmd = line_commands(start, end, n)
    origins, dirs = beam.rays(cmd)
    return cmd, origins, dirs


def light_plane(pivot_height_mm: float, start: np.ndarray, end: np.ndarray,
                telecentric: bool = False) -> np.ndarray:
    """Li et al. Eq. 2 in the world frame: plane through a, b, c as (4,) [A, B, C, D] with
    unit normal (A, B, C) and A x + B y + C z + D = 0. Telecentric: a = (x1, y1, H)."""
    b = np.array([start[0], start[1], 0.0])
    c = np.array([end[0], end[1], 0.0])
    a = np.array([b[0], b[1], pivot_height_mm]) if telecentric else np.array([0, 0, pivot_height_mm])
    (p, q, r), (x, y, z) = c - b, a - b
    n = np.array([q * z - r * y, r * x - p * z, p * y - q * x])    # (c − b) × (a − b)
    norm = np.linalg.norm(n)
    if norm < 1e-12:
        raise ValueError("light plane undefined: the line and the pivot are collinear")
    n /= norm
    return np.append(n, -n @ b)


AXIS_HALF_MM = 30.0


def axis_lines(half_mm: float = AXIS_HALF_MM) -> list[tuple[np.ndarray, np.ndarray]]:
    """The lines the head draws on the board for the camera ↔ scan-head alignment (Li et al.
    Case 1 step 1): x axis, y axis, +x half-axis (it tells +x from −x), (start, end) mm."""
    L = float(half_mm)
    return [(np.array([-L, 0.0]), np.array([L, 0.0])),
            (np.array([0.0, -L]), np.array([0.0, L])),
            (np.array([0.0, 0.0]), np.array([L, 0.0]))]
