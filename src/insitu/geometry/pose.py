"""The pose of a part lying flat on the table: a turn about +z and a shift — as the 4 × 4
``T_world_part`` that maps part-frame points (mm) into the world, or as a :data:`Pose4`
``(angle_rad, t)`` under which a point p maps to ``Rz(angle) @ p + t`` (t: (3,) mm)."""

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


Pose4 = tuple[float, np.ndarray]


def rot_z(angle_rad: float) -> np.ndarray:
    """(3, 3) rotation by ``angle_rad`` about +z."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def apply(pose: Pose4, points: np.ndarray) -> np.ndarray:
    """``points`` (N, 3) mapped by ``pose``."""
    return points @ rot_z(pose[0]).T + pose[1]


def inverse(pose: Pose4) -> Pose4:
    """The pose that undoes ``pose``."""
    return -pose[0], -(rot_z(-pose[0]) @ pose[1])


def matrix(pose: Pose4) -> np.ndarray:
    """(4, 4) homogeneous transform of ``pose``."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rot_z(pose[0]), pose[1]
    return T
