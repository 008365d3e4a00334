"""Consent to load native code: the station file.

A native library (an RTC DLL / .so, a GenTL producer .cti) runs its own code the moment it is
loaded, so insitu loads one only when the station's own configuration names it — never merely
because a rig file or a project does. The station file lives outside any project:
``$INSITU_STATION``, else ``$XDG_CONFIG_HOME/insitu/station.json`` (default
``~/.config/insitu/station.json``)::

    {"kind": "station", "schema_version": 1,
     "native_libraries": [{"path": "/opt/scanlab/librtc6.so", "sha256": "9f2c…"},
                          {"path": "/opt/mvIMPACT_Acquire/lib/x86_64/mvGenTLProducer.cti"}]}

Each ``path`` is absolute; both it and the library asked for are compared with symlinks
resolved; with ``sha256`` the file's contents must match too. No station file: nothing allowed.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from insitu.errors import ConfigError, DeviceError
from insitu.formats.validation import bad, read_json, validation_message

STATION_ENV = "INSITU_STATION"
SCHEMA_VERSION = 1


class NativeLibrary(BaseModel):
    model_config = ConfigDict(extra="forbid")
    path: str
    sha256: str | None = Field(None, pattern=r"^[0-9a-fA-F]{64}$")

    @field_validator("path")
    @classmethod
    def _absolute(cls, v: str) -> str:
        if not Path(v).expanduser().is_absolute():
            raise bad("expected an absolute path", v)
        return v


class StationFile(BaseModel):
    model_config = ConfigDict(extra="forbid")
    kind: Literal["station"] = "station"
    schema_version: int = Field(ge=1, le=SCHEMA_VERSION)
    native_libraries: list[NativeLibrary] = []


def station_path() -> Path:
    """Where this station's file is (it need not exist)."""
    if os.environ.get(STATION_ENV):
        return Path(os.environ[STATION_ENV]).expanduser().absolute()
    config = os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config"
    return Path(config) / "insitu" / "station.json"


def read_station(path: Path | None = None) -> StationFile | None:
    """The station file (None when there is none); ConfigError if it is not valid."""
    path = path or station_path()
    if not path.exists():
        return None
    data = read_json(path, error=ConfigError)
    try:
        return StationFile.model_validate(data)
    except ValidationError as e:
        raise ConfigError(validation_message(path, e)) from None


def _sha256(path: Path, what: str) -> str:
    h = hashlib.sha256()
    try:
        with path.open("rb") as f:
            while chunk := f.read(1 << 20):
                h.update(chunk)
    except OSError as e:
        raise DeviceError(f"{what}: cannot read the library {path} ({e.strerror or e})") from None
    return h.hexdigest()


def allowed_library(path: str | Path, what: str) -> Path:
    """``path`` with symlinks resolved, if the station file allows loading it. ``what`` names
    the setting that asks for it (``options.rtc.library``). DeviceError if it is not a file;
    ConfigError naming the library and the station file, and how to allow it, otherwise."""
    real = Path(path).expanduser().resolve()
    if not real.is_file():
        raise DeviceError(f"{what}: cannot load the library {path} (no such file)")
    where = station_path()
    station = read_station(where)
    how = (f'to allow it, add {{"path": "{real}"}} to native_libraries in {where}'
           + ("" if station is not None else ' (a JSON file {"kind": "station", '
              '"schema_version": 1, "native_libraries": [...]})'))
    entries = station.native_libraries if station is not None else []
    matches = [e for e in entries if Path(e.path).expanduser().resolve() == real]
    if not matches:
        plain = Path(os.path.abspath(Path(path).expanduser())) == real
        shown = real if plain else f"{path} (= {real})"
        raise ConfigError(f"{what}: native library {shown} is not allowed by the station "
                          f"file {where}{'' if station is not None else ' (none there)'}; "
                          f"nothing loaded: {how}")
    pinned = {e.sha256.lower() for e in matches if e.sha256}
    if pinned and _sha256(real, what) not in pinned:
        raise ConfigError(f"{what}: native library {real} differs from the sha256 the "
                          f"station file {where} allows; nothing loaded (update its sha256 "
                          "there if the library was updated on purpose)")
    return real
