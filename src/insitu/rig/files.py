"""Calibration and rig configuration files: readable JSON (mm, degrees), stored under ``calib/``.

Every calibration carries ``schema_version``, ``kind``, ``created`` (ISO-8601 UTC), ``units``,
the ``inputs`` it came from and its ``residuals`` (after mrcal's ``.cameramodel``). Load and
save with :func:`load_json_model` / :func:`save_json_model`; a file that is missing or not JSON
is a FormatError, one that does not fit its model a ConfigError, both naming file and field.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator

from insitu.errors import ConfigError, InsituError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.bounds import each_within, within
from insitu.formats.sequence import CameraSpec, ScanHeadSpec
from insitu.formats.validation import (Positive, Range, bad, dump_json, read_json,
                                       show, validation_message)
from insitu.geometry.beams import TwoMirrorHead

M = TypeVar("M", bound=BaseModel)
Pivot = within("pivot_height_mm")
MirrorDistance, MirrorSeparation = within("mirror_distance_mm"), within("mirror_separation_mm")
Seed = within("seed", int)


def utc_now() -> str:
    """Now as ISO-8601 UTC to the second, e.g. ``2024-05-01T12:00:00Z``."""
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


class JsonFile(BaseModel):
    """A model stored as one JSON file; remembers the path it was loaded from, if any."""

    SCHEMA_VERSION: ClassVar[int] = 1
    model_config = ConfigDict(extra="allow", allow_inf_nan=False)
    schema_version: int = 1
    _path: Path | None = PrivateAttr(default=None)

    @field_validator("schema_version")
    @classmethod
    def _known_version(cls, v: int) -> int:
        if not 1 <= v <= cls.SCHEMA_VERSION:
            raise bad(f"expected 1 to {cls.SCHEMA_VERSION} (this version of insitu)", v)
        return v

    @property
    def path(self) -> Path | None:
        """The file this was loaded from or last saved to."""
        return self._path


class CalibrationEnvelope(JsonFile):
    """What every calibration file carries besides its result."""

    kind: str
    created: str = Field(default_factory=utc_now)
    units: str = "mm"
    inputs: list[str] = []
    residuals: dict[str, float] = {}
    notes: str = ""

    @field_validator("created")
    @classmethod
    def _iso_time(cls, v: str) -> str:
        try:
            datetime.fromisoformat(v)
        except ValueError:
            raise bad("expected an ISO-8601 time such as '2024-05-01T12:00:00Z'", v) from None
        return v


class CameraCalibration(CalibrationEnvelope):
    """A calibrated camera (intrinsics px, extrinsics world → camera mm) and its residuals."""

    kind: Literal["camera"] = "camera"
    camera: CameraSpec
    rms_px: float | None = None
    per_view_rms_px: list[float] = []
    std_intrinsics: list[float] = []


class ScanHeadGeometry(ScanHeadSpec):
    """The scan head as the operator knows it — the one geometry type of insitu: the
    ``scan_head`` object of a recorded sequence (pivot height H, lens, usable field and focus
    range) plus the two-mirror distance d and separation e (Mikkelstrup et al.), mm."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    mirror_distance_mm: MirrorDistance
    mirror_separation_mm: MirrorSeparation

    def spec(self, mirrors: bool = False) -> dict:
        """The ``scan_head`` object of a recorded sequence (formats.md §1); with ``mirrors``
        also d and e (a field calibration's recording carries them)."""
        keys = set(ScanHeadSpec.model_fields) | (
            {"mirror_distance_mm", "mirror_separation_mm"} if mirrors else set())
        return self.model_dump(mode="json", include=keys)

    def two_mirror(self) -> TwoMirrorHead:
        """The nominal two-mirror kinematics."""
        return TwoMirrorHead(self.mirror_distance_mm, self.mirror_separation_mm)

    def geometry(self) -> "ScanHeadGeometry":
        """Just the geometry (of a file that carries more)."""
        return ScanHeadGeometry.model_validate(self.model_dump(
            include=set(ScanHeadGeometry.model_fields)))


class ScanHeadConfig(CalibrationEnvelope, ScanHeadGeometry):
    """The scan-head file (``calib/scan-head.json``): a :class:`ScanHeadGeometry` with the
    envelope every calibration file carries."""

    model_config = ConfigDict(extra="allow", frozen=False, allow_inf_nan=False)
    kind: Literal["scan-head"] = "scan-head"
    lens: Literal["non-telecentric", "telecentric"] = "non-telecentric"


class SheetModelSpec(BaseModel):
    """Our height model (insitu.measure.heightcal.SheetHeightModel)."""

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
    turned so that they run along y (insitu.measure.turned_sheet.TurnedSheetModel)."""

    line_angle_deg: within("line_angle_deg")


class PaperModelSpec(BaseModel):
    """Li et al.'s model (insitu.measure.heightcal.PaperHeightModel)."""

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
    """How line centres were extracted (insitu.vision.extract.CentreSettings)."""

    model_config = ConfigDict(allow_inf_nan=False)
    method: str = "steger"              # a key of insitu.vision.centres.CENTRE_METHODS
    k: float = Field(default=0.3, gt=0, lt=1)
    subtract: bool = False
    smooth_half_window: int = Field(default=7, ge=0, le=50)
    jump_px: Positive = 1.0
    end_fraction: float = Field(default=0.5, ge=0, lt=1)
    smooth_grains: float = Field(default=0.0, ge=0, le=100)    # 0: files before it: fixed
    background: bool = False                                    # files before it: Eq. 7
    extend_ends: bool = False                                   # files before it: none


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

    kind: Literal["height-calibration"] = "height-calibration"
    camera: CameraSpec
    centres: CentreSettingsSpec = CentreSettingsSpec()
    model: str = "sheet"                # a key of insitu.measure.height_models.HEIGHT_MODELS
    sheet: SheetModelSpec
    paper: PaperModelSpec | None = None
    sheet_cross: TurnedSheetSpec | None = None   # lines at an angle to x: a crossed scan
    residual_grid: ResidualGridSpec | None = None


class RigConfig(JsonFile):
    """Which backend drives each device, and where the calibration files are. Relative paths
    are relative to the rig file's folder (see :meth:`resolve`). Unknown fields are refused
    (this file is written by hand: a typo must not pass silently)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)
    kind: Literal["rig"] = "rig"
    camera: Literal["sim", "replay", "opencv", "genicam"] = "sim"
    scan_head: Literal["sim", "rtc", "lmc"] = "sim"
    stage: Literal["none", "sim", "grbl"] = "sim"
    camera_calibration: str | None = None
    scan_head_config: str | None = None
    height_calibration: str | None = None
    field_correction: str | None = None
    sim_seed: Seed = 0
    options: dict[str, Any] = {}

    @property
    def folder(self) -> Path:
        """The folder relative paths are taken from: the rig file's, else the current one."""
        return self._path.parent if self._path is not None else Path(".")

    def resolve(self, path: str | Path | None) -> Path | None:
        """``path`` (``~`` expanded) as absolute, or relative to :attr:`folder`; None stays None."""
        if path is None or path == "":
            return None
        p = Path(path).expanduser()
        return p if p.is_absolute() else self.folder / p


def _expected_kind(model: type[BaseModel]) -> str | None:
    field = model.model_fields.get("kind")
    return field.default if field is not None and isinstance(field.default, str) else None


def load_json_model(path: str | Path, model: type[M], error: type[InsituError] = ConfigError) -> M:
    """Read ``path`` as ``model``. Missing or not JSON: FormatError. Wrong ``kind``, newer
    ``schema_version`` or an invalid field: ``error`` (ConfigError), naming file and field."""
    path = Path(path)
    data = read_json(path)
    if isinstance(data, dict):
        kind = _expected_kind(model)
        if kind is not None and "kind" in data and data["kind"] != kind:
            raise error(f"{path}: kind: expected {kind!r}, got {show(data['kind'])}")
        version, newest = data.get("schema_version"), getattr(model, "SCHEMA_VERSION", None)
        if (newest is not None and isinstance(version, int) and not isinstance(version, bool)
                and version > newest):
            raise error(f"{path}: schema_version {version} is newer than this version of insitu "
                        f"reads (up to {newest}); update insitu to read it")
    try:
        obj = model.model_validate(data)
    except ValidationError as e:
        raise error(validation_message(path, e)) from None
    if isinstance(obj, JsonFile):
        obj._path = path
    return obj


def save_json_model(path: str | Path, model: BaseModel) -> None:
    """Write ``model`` to ``path`` atomically as indented JSON (FormatError if that fails)."""
    path = Path(path)
    atomic_write_text(path, dump_json(model.model_dump(mode="json")))
    if isinstance(model, JsonFile):
        model._path = path
