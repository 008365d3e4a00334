"""Pinhole camera with OpenCV distortion, in the world (scan-head) frame.

Extrinsics follow OpenCV: a world point X maps to camera coordinates ``R @ X + t``
(``T_cam_world``). Pixels: origin at the centre of the top-left pixel, u right, v down.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-14)


@dataclass(frozen=True, eq=False)
class CameraModel:
    """An intrinsically and extrinsically calibrated camera.

    width, height: image size, px. K: (3, 3). dist: (5,) or any OpenCV length.
    R: (3, 3) rotation, t: (3,) mm; together ``T_cam_world``.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    _rvec: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        for name, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if arr.shape != shape:
                raise ValueError(f"camera {name}: expected shape {shape}, got {arr.shape}")
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "dist", np.asarray(self.dist, dtype=np.float64).ravel())
        object.__setattr__(self, "_rvec", cv2.Rodrigues(self.R)[0])

    # -- frames ---------------------------------------------------------------------------
    @property
    def T_cam_world(self) -> np.ndarray:
        """(4, 4) homogeneous transform, world → camera."""
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self.R, self.t
        return T

    @property
    def centre_world(self) -> np.ndarray:
        """(3,) optical centre in the world frame, mm."""
        return -self.R.T @ self.t

    def to_camera(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 3) world points → (N, 3) camera-frame points, mm."""
        return np.asarray(points_world, dtype=np.float64) @ self.R.T + self.t

    def to_world(self, points_cam: np.ndarray) -> np.ndarray:
        """(N, 3) camera-frame points → (N, 3) world points, mm (the paper's Eq. 4)."""
        return (np.asarray(points_cam, dtype=np.float64) - self.t) @ self.R

    # -- projection -----------------------------------------------------------------------
    def project(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 3) world points, mm → (N, 2) distorted pixels (u, v). Points behind: NaN."""
        pts = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        uv, _ = cv2.projectPoints(pts, self._rvec, self.t, self.K, self.dist)
        uv = uv.reshape(-1, 2)
        uv[self.to_camera(pts)[:, 2] <= 0] = np.nan
        return uv

    def normalize(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) distorted pixels → (N, 2) undistorted normalised coordinates (x/z, y/z)."""
        pts = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4
            out = cv2.undistortPointsIter(pts, self.K, self.dist, None, None, _UNDISTORT_CRITERIA)
        else:
            out = cv2.undistortPoints(pts, self.K, self.dist, criteria=_UNDISTORT_CRITERIA)
        return out.reshape(-1, 2)

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) distorted pixels → (N, 2) ideal pinhole pixels with the same K."""
        xy = self.normalize(uv)
        return xy @ self.K[:2, :2].T + self.K[:2, 2]

    def rays(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Back-project (N, 2) pixels to world rays: origin (3,) and unit directions (N, 3)."""
        xy = self.normalize(uv)
        d_cam = np.column_stack([xy, np.ones(len(xy))])
        d = d_cam @ self.R  # R.T @ d for each row
        return self.centre_world, d / np.linalg.norm(d, axis=1, keepdims=True)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(N,) bool: pixel inside the image by at least ``margin`` px."""
        u, v = uv[:, 0], uv[:, 1]
        return (
            (u >= -0.5 + margin) & (u <= self.width - 0.5 - margin)
            & (v >= -0.5 + margin) & (v <= self.height - 0.5 - margin)
        )

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def look_at(
        cls, width: int, height: int, K: np.ndarray, dist: np.ndarray,
        centre: np.ndarray, target: np.ndarray, right: np.ndarray,
    ) -> "CameraModel":
        """Camera at ``centre`` looking at ``target``, image u along ``right`` (world vectors, mm)."""
        z = np.asarray(target, float) - np.asarray(centre, float)
        z /= np.linalg.norm(z)
        x = np.asarray(right, float) - np.dot(right, z) * z
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        R = np.vstack([x, y, z])
        return cls(width, height, K, dist, R, -R @ np.asarray(centre, float))

    def with_pose(self, R: np.ndarray, t: np.ndarray) -> "CameraModel":
        return CameraModel(self.width, self.height, self.K, self.dist, R, t)

    def to_dict(self) -> dict:
        """The ``camera`` object of a recorded sequence (docs/formats.md) (lists of floats)."""
        return {
            "width": int(self.width), "height": int(self.height),
            "K": self.K.tolist(), "dist": self.dist.tolist(),
            "R": self.R.tolist(), "t": self.t.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "CameraModel":
        return cls(int(d["width"]), int(d["height"]), np.array(d["K"]), np.array(d["dist"]),
                   np.array(d["R"]), np.array(d["t"]))


def rotation_about(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """(3, 3) rotation by ``angle_rad`` about ``axis`` (right hand)."""
    axis = np.asarray(axis, float)
    return cv2.Rodrigues(axis / np.linalg.norm(axis) * angle_rad)[0]
