"""The field correction file (``insitu calibrate field`` writes it, ``insitu galvo correct`` and
the scan-head driver read it): the fitted model of where the beam lands, the measurements it
was fitted to and its before/after residuals, mm.

:func:`correction_from_file` gives the function the driver needs: targets Q (N, 2) on z = 0 →
commands K (N, 2) such that the spot lands on Q. :data:`FIELD_METHODS` is the one table of
the models (``insitu calibrate field --method``, the file's ``method``): a new one is a module
with its model and selection, and here its file form and its entry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from insitu.calibrate.field import (
    DEFAULT_GOALS,
    DEFAULT_SMOOTHING,
    CorrectionTable,
    Model,
    RBFNetwork,
    Selection,
    invert,
    select_rbf,
    select_table,
)
from insitu.calibrate.field_areas import AreaStats
from insitu.errors import ConfigError
from insitu.formats.bounds import each_within, within
from insitu.formats.json_file import CalibrationEnvelope, load_json_model, save_json_model
from insitu.formats.sequence import CameraSpec
from insitu.formats.validation import Finite, PositivePair, Vec2, bad, numbers
from insitu.geometry.field import check_in_field

CONVENTION = ("landing(C) = C + delta(C) on z = 0 (delta = measured P - commanded Q); the "
              "command for target Q is the K with K + delta(K) = Q")
_STRICT = ConfigDict(extra="forbid", allow_inf_nan=False)
Sigma, MseGoal, Smoothing = within("rbf_sigma_mm"), within("mse_goal_mm2"), within("smoothing")
Position = within("position_mm")


class RBFSpec(BaseModel):
    """Mikkelstrup et al. Eqs. 7–8: g(x) = Σ w_j exp(-|x - c_j|² / 2σ²) + b, mm."""

    model_config = _STRICT
    sigma_mm: Sigma
    mse_goal_mm2: MseGoal
    centres_mm: Annotated[list[Vec2], Field(min_length=1), each_within("position_mm")]
    weights_mm: Annotated[list[Vec2], Field(min_length=1), each_within("rbf_weight_mm")]
    bias_mm: Annotated[Vec2, each_within("correction_mm")]

    @model_validator(mode="after")
    def _one_weight_per_centre(self) -> "RBFSpec":
        if len(self.weights_mm) != len(self.centres_mm):
            raise bad(f"expected {len(self.centres_mm)} weights (one per centre)",
                      f"{len(self.weights_mm)} weights", at="weights_mm")
        return self

    @classmethod
    def of(cls, model: RBFNetwork, mse_goal_mm2: float = 0.0, **_) -> "RBFSpec":
        return cls(sigma_mm=model.sigma, mse_goal_mm2=mse_goal_mm2,
                   centres_mm=model.centres.tolist(), weights_mm=model.weights.tolist(),
                   bias_mm=model.bias.tolist())

    def model(self) -> RBFNetwork:
        return RBFNetwork(np.array(self.centres_mm), np.array(self.weights_mm),
                          np.array(self.bias_mm), self.sigma_mm)

    def summary(self) -> str:
        return (f"RBF: σ = {self.sigma_mm:g} mm, MSE goal {self.mse_goal_mm2:g} mm², "
                f"{len(self.centres_mm)} neurons")

    def counts(self) -> dict[str, float]:
        return {"neurons": float(len(self.centres_mm))}


class TableSpec(BaseModel):
    """δ at grid nodes, ``values_mm[j][i]`` at (x_nodes_mm[i], y_nodes_mm[j]); bicubic
    not-a-knot spline between nodes."""

    model_config = _STRICT
    interpolation: Literal["bicubic-spline"] = "bicubic-spline"
    smoothing: Smoothing = 0.0
    x_nodes_mm: Annotated[list[Finite], Field(min_length=2), each_within("position_mm")]
    y_nodes_mm: Annotated[list[Finite], Field(min_length=2), each_within("position_mm")]
    values_mm: list[list[Annotated[Vec2, each_within("correction_mm")]]]

    @field_validator("x_nodes_mm", "y_nodes_mm")
    @classmethod
    def _increasing(cls, v: list[float]) -> list[float]:
        if any(b <= a for a, b in zip(v, v[1:])):
            raise bad("expected strictly increasing node positions", v)
        return v

    @model_validator(mode="after")
    def _grid(self) -> "TableSpec":
        nx, ny = len(self.x_nodes_mm), len(self.y_nodes_mm)
        if len(self.values_mm) != ny or any(len(r) != nx for r in self.values_mm):
            raise bad(f"expected {ny} rows of {nx} [dx, dy] values (y nodes × x nodes)",
                      f"{len(self.values_mm)} rows", at="values_mm")
        return self

    @classmethod
    def of(cls, model: CorrectionTable, **_) -> "TableSpec":
        return cls(smoothing=model.smoothing, x_nodes_mm=model.x_nodes.tolist(),
                   y_nodes_mm=model.y_nodes.tolist(), values_mm=model.values.tolist())

    def model(self) -> CorrectionTable:
        return CorrectionTable(np.array(self.x_nodes_mm), np.array(self.y_nodes_mm),
                               np.array(self.values_mm), self.smoothing)

    def summary(self) -> str:
        return (f"table: {len(self.x_nodes_mm)} × {len(self.y_nodes_mm)} nodes, smoothing "
                f"{self.smoothing:g}")

    def counts(self) -> dict[str, float]:
        return {}


@dataclass(frozen=True)
class FieldMethod:
    """A model of δ. ``select(X, D, extent, **options)`` → :class:`Selection`: fitted to
    commands X and deviations D (N, 2) mm, settings by 5-fold CV (``extent``: the field
    [x0, x1, y0, y1] mm; ``options``: sigmas, goals, smoothing — each method takes its own).
    ``spec``: its file form (``of(model, **cv_params)``, ``model()``, ``summary()``,
    ``counts()``), stored under the method's name; ``model_type``: the fitted model's class;
    ``description``: one line (CLI help)."""

    select: Callable[..., Selection]
    spec: type[BaseModel]
    model_type: type
    description: str


FIELD_METHODS: dict[str, FieldMethod] = {
    "rbf": FieldMethod(lambda X, D, extent, sigmas=None, goals=DEFAULT_GOALS, **_:
                       select_rbf(X, D, sigmas, goals), RBFSpec, RBFNetwork,
                       "RBF network trained by orthogonal least squares (Mikkelstrup et al.)"),
    "table": FieldMethod(lambda X, D, extent, smoothing=DEFAULT_SMOOTHING, **_:
                         select_table(X, D, extent, smoothing), TableSpec, CorrectionTable,
                         "correction table on a grid, spline-interpolated"),
}


class AreaRow(BaseModel):
    """Mikkelstrup Table 1 row: max and RMS of [|u_x|, |u_y|, |δ|] over an area, mm."""

    model_config = ConfigDict(allow_inf_nan=True)
    name: str
    n: int = Field(ge=0)
    max_mm: Annotated[list[float], numbers(3)]
    rms_mm: Annotated[list[float], numbers(3)]

    @classmethod
    def of(cls, s: AreaStats) -> "AreaRow":
        return cls(name=s.name, n=s.n, max_mm=list(s.max_mm), rms_mm=list(s.rms_mm))


class CVRow(BaseModel):
    """One setting tried: its parameters and the 5-fold CV RMS of |δ̂ − δ| (mm)."""

    params: dict[str, float]
    rms_mm: float
    fold_rms_mm: list[float]


class FieldCorrection(CalibrationEnvelope):
    """A scan-field correction (kind "field-correction"). ``region_mm`` [x0, x1, y0, y1]: the
    commands measured (the calibrated region); ``field_size_mm``: the head's usable field,
    centred on the origin — no target or command may leave it. The measurements: commands Q
    (``commands_mm``), landing points P (``landed_mm``) and the landing error expected after
    correction at each, out of fold (``after_mm``, = δ − δ̂ of 5-fold CV), mm."""

    kind: Literal["field-correction"] = "field-correction"
    convention: str = CONVENTION
    method: Literal[tuple(FIELD_METHODS)]       # a key of the table
    field_size_mm: Annotated[PositivePair, each_within("field_size_mm")]
    region_mm: Annotated[list[Finite], numbers(4), each_within("position_mm")]
    plate_z_mm: Position = 0.0
    camera: CameraSpec | None = None
    rbf: RBFSpec | None = None
    table: TableSpec | None = None
    cross_validation: list[CVRow] = []
    areas_before: list[AreaRow] = []
    areas_after: list[AreaRow] = []
    commands_mm: list[Vec2] = []
    landed_mm: list[Vec2] = []
    after_mm: list[Vec2] = []

    @model_validator(mode="after")
    def _has_its_model(self) -> "FieldCorrection":
        if getattr(self, self.method) is None:
            raise bad(f"missing (required when method is {self.method!r})", at=self.method)
        if len(self.commands_mm) != len(self.landed_mm):
            raise bad(f"expected {len(self.commands_mm)} points (one per command)",
                      f"{len(self.landed_mm)} points", at="landed_mm")
        return self

    def delta(self) -> Model:
        """δ(C): (N, 2) commands → (N, 2) predicted landing shifts, mm."""
        return getattr(self, self.method).model()

    def outside_region(self, targets: np.ndarray) -> np.ndarray:
        """(N,) bool: targets outside the calibrated region (the correction extrapolates)."""
        x0, x1, y0, y1 = self.region_mm
        t = np.asarray(targets, np.float64).reshape(-1, 2)
        return (t[:, 0] < x0 - 1e-9) | (t[:, 0] > x1 + 1e-9) | (t[:, 1] < y0 - 1e-9) | \
            (t[:, 1] > y1 + 1e-9)

    def correct(self, targets: np.ndarray, where: str = "target") -> np.ndarray:
        """Commands K (N, 2) that land on ``targets`` (N, 2), mm. SafetyError naming the first
        target (``where`` and its 1-based number) outside the field, or whose command would
        leave it."""
        Q = np.asarray(targets, np.float64).reshape(-1, 2)
        check_in_field(Q, self.field_size_mm, lambda i, field: f"{where} {i + 1}: {_xy(Q[i])} "
                       f"mm is outside the scan field {field}")
        if not len(Q):
            return Q.copy()
        K = invert(self.delta(), Q)
        check_in_field(K, self.field_size_mm, lambda i, field: f"{where} {i + 1}: {_xy(Q[i])} "
                       f"mm needs the command {_xy(K[i])} mm, outside the scan field {field}",
                       at=Q)
        return K


def _xy(p: np.ndarray) -> str:
    return f"[{p[0]:.4g}, {p[1]:.4g}]"


def load_field_correction(path: str | Path) -> FieldCorrection:
    """Read a field correction file (FormatError if missing/not JSON, ConfigError if invalid
    or of another kind)."""
    return load_json_model(path, FieldCorrection, ConfigError)


def save_field_correction(path: str | Path, correction: FieldCorrection) -> None:
    """Write atomically as indented JSON."""
    save_json_model(path, correction)


def correction_from_file(path: str | Path) -> Callable[[np.ndarray], np.ndarray]:
    """targets Q (N, 2) → corrected commands K (N, 2), mm, from the file at ``path``."""
    correction = load_field_correction(path)
    return correction.correct


def model_spec(model: Any, mse_goal_mm2: float = 0.0) -> dict:
    """``{method: spec}`` (e.g. ``{"rbf": RBFSpec}``) for a fitted model."""
    for name, m in FIELD_METHODS.items():
        if isinstance(model, m.model_type):
            return {name: m.spec.of(model, mse_goal_mm2=mse_goal_mm2)}
    raise TypeError(f"not a field model: {type(model).__name__}")
