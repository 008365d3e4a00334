"""POSE.json: where ``insitu locate`` found a part — ``T_world_part`` (4 × 4, part frame →
world, mm), x, y, z, the turn about z, the fit (fitness, coverage, inlier RMSE), the second
best distinct solution, and the inputs. Written atomically; read back with one-line errors
naming the file and the field."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, field_validator

from insitu.errors import ConfigError
from insitu.formats.bounds import within
from insitu.formats.json_file import CalibrationEnvelope, load_json_model, save_json_model
from insitu.formats.validation import bad

Mm, Deg, Share = within("position_mm"), within("angle_deg"), within("fraction")
Rmse = within("residual_mm")
Count, Seconds = within("point_count", int), within("duration_s")


class SolutionSpec(BaseModel):
    """The second best distinct solution: its pose and fit."""

    model_config = ConfigDict(allow_inf_nan=False)
    x_mm: Mm
    y_mm: Mm
    z_mm: Mm
    angle_deg: Deg
    fitness: Share
    coverage: Share
    rmse_mm: Rmse
    score: Share | None = None


class PoseFile(CalibrationEnvelope):
    """A located part (see the module's docstring)."""

    kind: Literal["part-pose"] = "part-pose"
    units: str = "mm, degrees"
    T_world_part: list[list[float]]
    x_mm: Mm
    y_mm: Mm
    z_mm: Mm
    angle_deg: Deg
    fitness: Share
    coverage: Share
    inlier_rmse_mm: Rmse
    edge_samples: Count = 0
    sigma_mm: Rmse | None = None
    sigma_deg: Deg | None = None
    sigma_rim_mm: Rmse | None = None
    tolerance_mm: Rmse | None = None
    turn_bound_deg: Deg | None = None
    second: SolutionSpec | None = None
    table_z_mm: Mm | None = None
    points: Count = 0
    seconds: Seconds = 0.0
    prefer_angle_deg: list[Deg] | None = None
    rig: dict | None = None

    @field_validator("T_world_part")
    @classmethod
    def _flat_rigid(cls, v: list[list[float]]) -> list[list[float]]:
        T = np.asarray(v, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise bad("expected a 4 × 4 matrix of numbers", v)
        R = T[:3, :3]
        if (not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or abs(T[2, 2] - 1) > 1e-6
                or not np.allclose(T[3], [0, 0, 0, 1])):
            raise bad("expected a turn about z and a shift (the part lies flat): "
                      "[[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1]]", v)
        if np.any(np.abs(T[:3, 3]) > 1000):
            raise bad("the shift is outside -1000 … 1000 mm", v)
        return v

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) float64 ``T_world_part``."""
        return np.asarray(self.T_world_part, dtype=float)


def save_pose(path: str | Path, d: dict, inputs: list[str],
              prefer_angle: tuple[float, float] | None = None, rig: dict | None = None) -> None:
    """Write the located pose ``d`` (``insitu.locate.part.PartPose.to_dict()``: the fields of
    :class:`PoseFile`) to ``path`` atomically, with its ``inputs`` (file names)."""
    save_json_model(path, PoseFile(
        inputs=inputs, residuals={"inlier_rmse_mm": d["inlier_rmse_mm"],
                                  "fitness": d["fitness"], "coverage": d["coverage"]},
        prefer_angle_deg=list(prefer_angle) if prefer_angle is not None else None, rig=rig,
        **d))


def load_pose(path: str | Path) -> PoseFile:
    """POSE.json read and checked: FormatError (missing, not JSON) or ConfigError (a field
    out of range, a tilted or non-rigid ``T_world_part``), one line naming file and field."""
    return load_json_model(path, PoseFile, ConfigError)
