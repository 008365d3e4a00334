"""The camera and height calibration files (``insitu calibrate camera``, ``insitu calibrate
height``), written under ``calib/`` and read back by scans and the station."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from insitu.formats.bounds import each_within, within
from insitu.formats.json_file import CalibrationEnvelope
from insitu.formats.migrations import newest
from insitu.formats.sequence import CameraSpec
from insitu.formats.validation import Positive, Range, bad

Pivot = within("pivot_height_mm")


class CameraCalibration(CalibrationEnvelope):
    """A calibrated camera (intrinsics px, extrinsics world → camera mm) and its residuals."""

    kind: Literal["camera"] = "camera"
    camera: CameraSpec
    rms_px: float | None = None
    per_view_rms_px: list[float] = []
    std_intrinsics: list[float] = []


class SheetModelSpec(BaseModel):
    """Our height model (insitu.reconstruct.plate_models.SheetHeightModel)."""

    model_config = ConfigDict(allow_inf_nan=False)
    pivot_height_mm: Pivot
    exponents: Annotated[list[tuple[int, int, int]], Field(min_length=1),
                         each_within("exponent")]
    coefficients_mm: Annotated[list[float], Field(min_length=1), each_within("coefficient_mm")]
    scale_mm: Annotated[tuple[float, float, float], each_within("scale_mm")]
    x_range_mm: Annotated[Range, each_within("position_mm")]
    z_range_mm: Annotated[Range, each_within("position_mm")]

    @field_validator("coefficients_mm")
    @classmethod
    def _one_per_term(cls, v: list[float], info) -> list[float]:
        n = len(info.data.get("exponents", []))
        if n and len(v) != n:
            raise bad(f"expected {n} coefficients (one per exponent)", f"{len(v)} values")
        return v


class TurnedSheetSpec(SheetModelSpec):
    """Our height model of the crossed lines, at ``line_angle_deg`` to x, fitted in the world
    turned so that they run along y (insitu.reconstruct.turned_sheet.TurnedSheetModel)."""

    line_angle_deg: within("line_angle_deg")


class PaperModelSpec(BaseModel):
    """Li et al.'s model (insitu.reconstruct.plate_models.PaperHeightModel)."""

    model_config = ConfigDict(allow_inf_nan=False)
    ref_u: Annotated[list[float], Field(min_length=5), each_within("pixel_px")]
    ref_v: Annotated[list[float], Field(min_length=5), each_within("pixel_px")]
    offsets_mm: Annotated[list[float], Field(min_length=2), each_within("position_mm")]
    heights_mm: Annotated[list[float], Field(min_length=2), each_within("position_mm")]
    P_px: Annotated[list[list[float]], each_within("pixel_px")]

    @field_validator("P_px")
    @classmethod
    def _grid(cls, v: list[list[float]], info) -> list[list[float]]:
        k, j = len(info.data.get("offsets_mm", [])), len(info.data.get("heights_mm", []))
        if k and j and (len(v) != k or any(len(r) != j for r in v)):
            raise bad(f"expected a {k} × {j} grid (offsets × heights)", f"{len(v)} rows")
        return v


class CentreSettingsSpec(BaseModel):
    """How line centres were extracted (insitu.vision.extract.CentreSettings), every
    setting written (:mod:`insitu.formats.migrations` fills in what older files left out)."""

    model_config = ConfigDict(allow_inf_nan=False)
    method: str                         # a key of insitu.vision.centres.CENTRE_METHODS
    k: float = Field(gt=0, lt=1)
    subtract: bool
    smooth_half_window: int = Field(ge=0, le=50)
    jump_px: Positive
    end_fraction: float = Field(ge=0, lt=1)
    smooth_grains: float = Field(ge=0, le=100)
    background: bool
    extend_ends: bool


class ResidualGridSpec(BaseModel):
    """RMS height error of the default model per plate height (rows) and line offset
    (columns), mm; null where the recording had no frame."""

    model_config = ConfigDict(allow_inf_nan=False)
    heights_mm: list[float] = Field(min_length=1)
    offsets_mm: list[float] = Field(min_length=1)
    rms_mm: list[list[float | None]]

    @field_validator("rms_mm")
    @classmethod
    def _grid(cls, v: list[list[float | None]], info) -> list[list[float | None]]:
        h, x = len(info.data.get("heights_mm", [])), len(info.data.get("offsets_mm", []))
        if h and x and (len(v) != h or any(len(r) != x for r in v)):
            raise bad(f"expected a {h} × {x} grid (heights × offsets)", f"{len(v)} rows")
        return v


class HeightCalibration(CalibrationEnvelope):
    """Height calibration (Li et al. §2.2 and ours) with the camera it was fitted through and
    the centre extraction it was made with (a scan must use the same). ``model``: the default
    one; each model under its name; ``sheet_cross``: the crossed lines' (None: the recording
    had lines along y only, so it cannot scan crossed). ``model`` and ``centres.method`` are
    checked against their tables by :func:`insitu.services.height.load_height_calibration`
    (the tables live above this layer)."""

    SCHEMA_VERSION: ClassVar[int] = newest("height-calibration")
    kind: Literal["height-calibration"] = "height-calibration"
    schema_version: int = SCHEMA_VERSION
    camera: CameraSpec
    centres: CentreSettingsSpec
    model: str = "sheet"                # a key of insitu.reconstruct.height_models.HEIGHT_MODELS
    sheet: SheetModelSpec
    paper: PaperModelSpec | None = None
    sheet_cross: TurnedSheetSpec | None = None   # lines at an angle to x: a crossed scan
    residual_grid: ResidualGridSpec | None = None


