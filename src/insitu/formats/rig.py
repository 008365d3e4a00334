"""The rig file (which backend drives each device, where the calibrations are) and the scan
head's geometry file (``calib/scan-head.json``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import ConfigDict

from insitu.formats.bounds import within
from insitu.formats.json_file import CalibrationEnvelope, JsonFile
from insitu.formats.sequence import ScanHeadSpec

MirrorDistance, MirrorSeparation = within("mirror_distance_mm"), within("mirror_separation_mm")
Seed = within("seed", int)


class ScanHeadGeometry(ScanHeadSpec):
    """The scan head as the operator knows it — the one geometry type of insitu: the
    ``scan_head`` object of a recorded sequence (pivot height H, lens, usable field and focus
    range) plus the two-mirror distance d and separation e (Mikkelstrup et al.), mm."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    mirror_distance_mm: MirrorDistance
    mirror_separation_mm: MirrorSeparation

    def spec(self, mirrors: bool = False) -> dict:
        """The ``scan_head`` object of a recorded sequence (docs/formats.md); with ``mirrors``
        also d and e (a field calibration's recording carries them)."""
        keys = set(ScanHeadSpec.model_fields) | (
            {"mirror_distance_mm", "mirror_separation_mm"} if mirrors else set())
        return self.model_dump(mode="json", include=keys)

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


