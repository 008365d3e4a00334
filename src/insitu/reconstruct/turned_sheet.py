"""The height model of a crossed pass: lines at ``angle_deg`` to x instead of along y.

:class:`~insitu.reconstruct.plate_models.SheetHeightModel` knows lines along y (constant x) only.
Turn the whole problem about z — the world and the camera by β = 90° − angle — and the
crossed lines run along y; the same sheet model is fitted and evaluated there and its points
are turned back. The nominal pivot model X = x (H − Z) / H is the same in any turned frame;
the polynomial absorbs what differs (the two mirrors, the head's distortion).

Why not lines along x: a side camera that looks along x (as the simulated rig's does, from
−x) lies nearly in every light sheet of a line along x, so it sees those sheets edge-on and
cannot triangulate them (Method 1 on the simulated rig: heights scatter by 6 … 185 mm).
Lines at 45° keep 70 % of the baseline of lines along y (0.08 … 0.14 mm scatter, as along
y); that is :data:`CROSS_ANGLE_DEG`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.geometry.camera import CameraModel
from insitu.geometry.pose import rot_z
from insitu.reconstruct.plate_models import SheetHeightModel

CROSS_ANGLE_DEG = 45.0
"""The crossed pass's line direction, degrees from +x (lines along y are at 90°)."""


def line_angle(start, end) -> float:
    """The direction of the line start → end, degrees from +x in [0, 180) (to 1e-9°, so the
    lines a plan draws at 45° are at 45°)."""
    d = np.asarray(end, float)[:2] - np.asarray(start, float)[:2]
    return float(round(np.degrees(np.arctan2(d[1], d[0])) % 180.0, 9) % 180.0)


def same_direction(start, end, angle_deg: float, tol_deg: float = 1e-4) -> bool:
    """True when the line start → end runs at ``angle_deg`` to x (either way along)."""
    diff = (line_angle(start, end) - angle_deg + 90.0) % 180.0 - 90.0
    return abs(diff) <= tol_deg


def turn_to_y(angle_deg: float) -> np.ndarray:
    """(3, 3) Rz(90° − angle): turns lines at ``angle_deg`` to x onto the y axis."""
    return rot_z(np.radians(90.0 - angle_deg))


def turned_camera(camera: CameraModel, angle_deg: float) -> CameraModel:
    """The same camera in the turned world (p' = Rz p): ``R Rzᵀ`` with the same ``t``."""
    return CameraModel(camera.width, camera.height, camera.K, camera.dist,
                       camera.R @ turn_to_y(angle_deg).T, camera.t)


def turned_offset(start, end, angle_deg: float) -> float:
    """The line's offset in the turned frame: its constant x' there, mm."""
    R = turn_to_y(angle_deg)[:2, :2]
    mid = (np.asarray(start, float)[:2] + np.asarray(end, float)[:2]) / 2
    return float((R @ mid)[0])


def turned_lines(offsets, span: tuple[float, float], angle_deg: float
                 ) -> list[tuple[np.ndarray, np.ndarray]]:
    """World lines (start, end) mm at ``angle_deg`` to x: the lines x' = offset, y' from
    span[0] to span[1] of the turned frame, turned back."""
    Rt = turn_to_y(angle_deg)[:2, :2].T
    return [(Rt @ np.array([x, span[0]], float), Rt @ np.array([x, span[1]], float))
            for x in map(float, offsets)]


@dataclass(frozen=True)
class TurnedSheetModel:
    """``sheet`` fitted in the world turned so that lines at ``angle_deg`` to x run along y;
    :meth:`points` takes the line's offset in that frame (:func:`turned_offset`)."""

    angle_deg: float
    sheet: SheetHeightModel

    name = "sheet"

    @property
    def z_range(self) -> tuple[float, float]:
        return self.sheet.z_range

    def points(self, camera: CameraModel, x_mm: float, u: np.ndarray, v: np.ndarray
               ) -> np.ndarray:
        """(N, 3) world mm of the centres (u, v) of the line at turned offset ``x_mm``."""
        p = self.sheet.points(turned_camera(camera, self.angle_deg), x_mm, u, v)
        return p @ turn_to_y(self.angle_deg)          # p = Rzᵀ p', row-wise

    def to_dict(self) -> dict:
        return {"line_angle_deg": self.angle_deg, **self.sheet.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> "TurnedSheetModel":
        d = dict(d)
        return cls(float(d.pop("line_angle_deg")), SheetHeightModel.from_dict(d))
