"""The pose of a part lying flat on the table: a turn about +z and a shift, as the 4 × 4
``T_world_part`` that maps part-frame points (mm) into the world."""

from __future__ import annotations

import math

import numpy as np


def pose_matrix(x_mm: float, y_mm: float, angle_deg: float) -> np.ndarray:
    """T_world_part (4, 4) float64 of a part turned by ``angle_deg`` about +z through its
    origin, then moved by (``x_mm``, ``y_mm``)."""
    a = math.radians(angle_deg)
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
    T[:2, 3] = x_mm, y_mm
    return T


def flat_pose(T_world_part: np.ndarray) -> tuple[float, float, float]:
    """(x mm, y mm, angle_deg in −180 … 180) of ``T_world_part`` (4, 4): its shift and its
    turn about +z."""
    T = np.asarray(T_world_part, float)
    return float(T[0, 3]), float(T[1, 3]), math.degrees(math.atan2(T[1, 0], T[0, 0]))
