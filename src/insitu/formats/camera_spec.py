"""The camera as a recording or a rig file holds it (docs/formats.md, recorded sequence
``camera``): intrinsics, OpenCV distortion and the world → camera pose, each value checked
against its range."""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, field_validator

from insitu.formats.bounds import BOUNDS, each_within, within
from insitu.formats.validation import Finite, Matrix3, Vec3, bad, numbers

_CONFIG = ConfigDict(extra="allow", allow_inf_nan=False)
ImagePx = within("image_px", int)
_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tx", "ty")
_DIST_BOUND = {"k1": "dist_k1", "p1": "dist_tangential", "p2": "dist_tangential"}


class CameraSpec(BaseModel):
    """The rig's camera as known to the operator: intrinsics K (px), OpenCV distortion, and
    extrinsics mapping a world point X (mm) to camera coordinates ``R @ X + t``."""

    model_config = _CONFIG
    width: ImagePx
    height: ImagePx
    K: Annotated[Matrix3, each_within("pixel_px")]
    dist: Annotated[list[Finite], numbers(4, 5, 8, 12, 14, what=" (OpenCV distortion)")]
    R: Matrix3
    t: Annotated[Vec3, each_within("camera_t_mm")]

    @field_validator("K")
    @classmethod
    def _intrinsics(cls, K: list[list[float]]) -> list[list[float]]:
        if not (K[0][0] > 0 and K[1][1] > 0):
            raise bad("expected fx = K[0][0] > 0 and fy = K[1][1] > 0", K)
        for i in (0, 1):
            why = BOUNDS["focal_px"].problem(K[i][i])
            if why is not None:
                raise bad(f"{'fx' if i == 0 else 'fy'} = {why}", at=f"[{i}][{i}]")
        if K[2] != [0, 0, 1]:
            raise bad("expected [0, 0, 1]", K[2], at="[2]")
        return K

    @field_validator("dist")
    @classmethod
    def _distortion(cls, dist: list[float]) -> list[float]:
        for i, (name, value) in enumerate(zip(_DIST_NAMES, dist)):
            why = BOUNDS[_DIST_BOUND.get(name, "dist_other")].problem(value)
            if why is not None:
                raise bad(f"{name} = {why}", at=f"[{i}]")
        return dist

    @field_validator("R")
    @classmethod
    def _rotation(cls, R: list[list[float]]) -> list[list[float]]:
        a = np.asarray(R, np.float64)
        if np.abs(a).max() > 1.0 + 1e-6:                # a rotation's entries are within ±1
            raise bad("expected a rotation matrix (entries within ±1)", R)
        err, det = float(np.abs(a @ a.T - np.eye(3)).max()), float(np.linalg.det(a))
        if err > 1e-6 or det <= 0:
            raise bad("expected a rotation matrix (R @ R.T = I within 1e-6, det +1), got "
                      f"max |R @ R.T - I| = {err:.3g}, det = {det:.6g}")
        return R

    K_array = property(lambda self: np.array(self.K, np.float64), doc="(3, 3) float64, px.")
    dist_array = property(lambda self: np.array(self.dist, np.float64),
                          doc="(N,) float64, OpenCV order [k1, k2, p1, p2, k3, ...].")
    R_array = property(lambda self: np.array(self.R, np.float64),
                       doc="(3, 3) float64 rotation, world → camera.")
    t_array = property(lambda self: np.array(self.t, np.float64),
                       doc="(3,) float64 translation, mm, world → camera.")
