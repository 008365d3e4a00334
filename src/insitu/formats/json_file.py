"""JSON files of insitu's own (calibrations, the rig file, poses): readable JSON (mm, degrees).

Every calibration carries ``schema_version``, ``kind``, ``created`` (ISO-8601 UTC), ``units``,
the ``inputs`` it came from and its ``residuals`` (after mrcal's ``.cameramodel``). Load and
save with :func:`load_json_model` / :func:`save_json_model`; a file that is missing or not JSON
is a FormatError, one that does not fit its model a ConfigError, both naming file and field.
A file written by an older version of insitu is brought up to date by
:mod:`insitu.formats.migrations` before it is validated.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path
from typing import ClassVar, TypeVar

from pydantic import BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator

from insitu.errors import ConfigError, InsituError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.migrations import migrate
from insitu.formats.validation import bad, dump_json, read_json, show, validation_message

M = TypeVar("M", bound=BaseModel)


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
        data = migrate(kind, data)
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
