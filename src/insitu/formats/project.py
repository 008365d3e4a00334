"""The project file of ``insitu gui``: one JSON file holding the whole session — rig,
calibration references, cloud, placed patterns, job — with paths relative to the file.

    {"format": "insitu-project/1", "schema_version": 1, "saved": "...Z",
     "rig": {"workpiece": "step-block", "seed": 0, "binning": 1, "rig_file": null},
     "calibration": {"height": "calib/height.json", "field": null, "camera": null},
     "scan": {"region": [-15, 15, -45, 45], "spacing_mm": 0.5, "exposure_ms": 10, "replay": null},
     "cloud": "part.cloud.ply",
     "placements": [{"pattern": "logo.svg", "at_mm": [0, 25], "width_mm": 12, ...,
                     "pen": "deep"}],
     "selected": 0, "job": "part.job.json",
     "pens": [{"name": "mark", "power_pct": 30, ...}, ...], "default_pen": "mark"}

``pens`` (optional; :mod:`insitu.formats.pens`): the project's pen table; a placement's
``pen`` names one of them (of :data:`~insitu.formats.pens.DEFAULT_PENS` without a table).

Saving (:func:`insitu.services.project.save_project`) writes the cloud (if it is not on disk
yet) and the job beside the project first, then the project file, each atomically. Loading
validates every field and checks that the files it names exist; errors are one-line
FormatErrors naming the file and the field. The placed patterns are the caller's dataclass
(``insitu.services.mark.Placement``), passed in to :func:`read_project`.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Collection
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.bounds import each_within, within
from insitu.formats.pens import DEFAULT_PENS, PenName, PenTable, pen_table, pens_dict, read_pens
from insitu.formats.validation import dump_json, one_of, read_json, validation_message

PROJECT_FORMAT = "insitu-project/1"
SCHEMA_VERSION = 1
SUFFIX = ".insitu.json"
_SPEC = re.compile(r"^[a-z][a-z0-9-]+:")
"""A pattern spec ``kind:payload`` (``text:…``, ``qr:…``); anything else is a file (a drive
letter ``C:`` is one character)."""


SIM_BINNING = 1
"""The simulated rig's binning wherever none is given: the commands, the GUI, a new project
(the demo's and the docs' recordings and calibrations are made at it)."""


@dataclass(frozen=True)
class RigChoice:
    """Which rig: the simulated one (``workpiece``, ``seed``, ``binning``: image size divided
    by it) or the one a ``rig_file`` describes (the workpiece still chooses the simulated
    part while the backends are "sim")."""

    workpiece: str = "step-block"
    seed: int = 0
    binning: int = SIM_BINNING
    rig_file: Path | None = None


@dataclass(frozen=True)
class ScanSettings:
    """``region``: (x0, x1, y0, y1) mm, None for the part's footprint; ``spacing_mm``
    between lines; ``exposure_ms`` of the camera; ``replay``: a recorded scan folder to
    reconstruct instead of driving the rig; ``speed_mm_s``: how fast the head sweeps a line."""

    region: tuple[float, float, float, float] | None = None
    spacing_mm: float = 0.5
    exposure_ms: float = 10.0
    replay: Path | None = None
    speed_mm_s: float = 2000.0


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


Seed, Binning = within("seed", int), within("binning", int)
Region = Annotated[tuple[float, float, float, float], each_within("position_mm")]
Spacing, Speed, Length = within("spacing_mm"), within("mark_speed_mm_s"), within("length_mm")
Angle, Exposure = within("angle_deg"), within("exposure_ms")


class _Rig(_Strict):
    workpiece: str = "step-block"
    seed: Seed = 0
    binning: Binning = SIM_BINNING
    rig_file: str | None = None


class _Calibration(_Strict):
    height: str | None = None
    field: str | None = None
    camera: str | None = None


class _Scan(_Strict):
    region: Region | None = None
    spacing_mm: Spacing = 0.5
    exposure_ms: Exposure = 10.0
    replay: str | None = None
    speed_mm_s: Speed = 2000.0


class _Placement(_Strict):
    pattern: str = Field(min_length=1)
    at_mm: Annotated[tuple[float, float], each_within("position_mm")]
    width_mm: Length
    rotate_deg: Angle = 0.0
    mode: str = "planar"                 # a projection mode: read_project checks it
    hatch_mm: Length | None = None
    hatch_angle_deg: Angle = 0.0
    cross: bool = False
    fill: Literal["auto", "all", "none"] = "auto"   # a DXF's closed outlines
    beam_mm: Length = 0.05                         # strokes this wide or more: areas
    pen: PenName | None = None                     # a pen of the table: read_project checks
    paint: Literal["threshold", "dither"] = "threshold"   # an SVG's shaded paints


class _Project(_Strict):
    format: Literal["insitu-project/1"]
    schema_version: int = Field(ge=1)
    saved: str | None = None
    rig: _Rig = _Rig()
    calibration: _Calibration = _Calibration()
    scan: _Scan = _Scan()
    cloud: str | None = None
    placements: list[_Placement] = []
    selected: int = -1
    job: str | None = None
    pens: list[Any] | None = None                  # checked by pen_table
    default_pen: str | None = None


@dataclass
class Project:
    """A project in memory, every path absolute. ``cloud`` is the .ply to read (load) or the
    one the cloud already is in (save; None: write it beside the project). ``placements``:
    dataclasses with the fields of a placement (pattern, at_mm, width_mm, rotate_deg, mode,
    hatch_mm, hatch_angle_deg, cross, fill, beam_mm, pen); ``pens``: the pen table (None:
    none saved, :data:`~insitu.formats.pens.DEFAULT_PENS` apply)."""

    rig: RigChoice = field(default_factory=RigChoice)
    height_cal: Path | None = None
    field_correction: Path | None = None
    camera_cal: Path | None = None
    scan: ScanSettings = field(default_factory=ScanSettings)
    cloud: Path | None = None
    placements: tuple[Any, ...] = ()
    selected: int = -1
    job: Path | None = None
    pens: PenTable | None = None


def beside(path: str | Path, suffix: str) -> Path:
    """The file named after project ``path`` with ``suffix`` (``p.insitu.json`` →
    ``p.job.json`` for ".job.json")."""
    path = Path(path)
    stem = path.name[:-len(SUFFIX)] if path.name.endswith(SUFFIX) else path.stem
    return path.with_name(stem + suffix)


def _rel(path: Path | None, folder: Path) -> str | None:
    if path is None:
        return None
    return Path(os.path.relpath(Path(path).resolve(), folder.resolve())).as_posix()


def _abs(text: str | None, folder: Path, where: str, source: Path, must_exist=True
         ) -> Path | None:
    if text is None:
        return None
    try:
        p = Path(text).expanduser()
        p = p if p.is_absolute() else Path(os.path.normpath(folder / p))
        found = not must_exist or p.exists()
    except (OSError, RuntimeError, ValueError) as e:    # too long, a NUL, no home for ~user
        raise FormatError(f"{source}: {where}: not a usable path ({str(e)[:80]})") from None
    if not found:
        raise FormatError(f"{source}: {where}: {text} not found (looked for {p})")
    return p


def project_json(project: Project, path: Path) -> str:
    """The text of the project file at ``path`` (paths made relative to its folder)."""
    folder = Path(path).parent
    placements = []
    for p in project.placements:
        d = asdict(p)
        d["pattern"] = p.pattern if _SPEC.match(p.pattern) else _rel(Path(p.pattern), folder)
        placements.append(d)
    scan = project.scan
    data = _Project(
        format=PROJECT_FORMAT, schema_version=SCHEMA_VERSION,
        saved=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        rig=_Rig(workpiece=project.rig.workpiece, seed=project.rig.seed,
                 binning=project.rig.binning, rig_file=_rel(project.rig.rig_file, folder)),
        calibration=_Calibration(height=_rel(project.height_cal, folder),
                                 field=_rel(project.field_correction, folder),
                                 camera=_rel(project.camera_cal, folder)),
        scan=_Scan(region=scan.region, spacing_mm=scan.spacing_mm,
                   exposure_ms=scan.exposure_ms, replay=_rel(scan.replay, folder),
                   speed_mm_s=scan.speed_mm_s),
        cloud=_rel(project.cloud, folder), placements=placements,
        selected=project.selected, job=_rel(project.job, folder),
        **({} if project.pens is None else {"pens": pens_dict(project.pens)["pens"],
                                            "default_pen": project.pens.default}))
    unset = {"pens", "default_pen"} if project.pens is None else None
    return dump_json(data.model_dump(mode="json", exclude=unset)) + "\n"


def write_project(path: str | Path, project: Project) -> None:
    """Write the project file atomically (the cloud and job it names must be on disk)."""
    path = Path(path)
    atomic_write_text(path, project_json(project, path))


def load_pens(path: str | Path) -> PenTable:
    """The pens of a pens file, or of a project (:data:`DEFAULT_PENS` when it saved none)."""
    path = Path(path)
    if not path.name.endswith(SUFFIX):
        return read_pens(path)
    raw = read_json(path)
    if not isinstance(raw, dict) or raw.get("format") != PROJECT_FORMAT:
        raise FormatError(f"{path}: format: expected {PROJECT_FORMAT!r} (a project's pens)")
    if raw.get("pens") is None:
        return DEFAULT_PENS
    return pen_table(raw["pens"], raw.get("default_pen"), path, "default_pen")


def check_header(path: Path, raw, fmt: str, what: str, schema_version: int) -> None:
    """FormatError unless ``raw`` (a file's JSON) is a dict of ``format`` ``fmt`` and a
    ``schema_version`` this insitu reads."""
    if not isinstance(raw, dict) or raw.get("format") != fmt:
        got = raw.get("format") if isinstance(raw, dict) else type(raw).__name__
        raise FormatError(f"{path}: format: expected {fmt!r}, got {got!r} (not {what})")
    if isinstance(raw.get("schema_version"), int) and raw["schema_version"] > schema_version:
        raise FormatError(f"{path}: schema_version {raw['schema_version']}: this version of "
                          f"insitu reads up to {schema_version}")


def read_project(path: str | Path, placement: Callable[..., Any],
                 modes: Collection[str]) -> Project:
    """Read and validate a project file; FormatError naming the file and the field. Each
    placed pattern is made by ``placement(pattern, at_mm, width_mm, rotate_deg, mode,
    hatch_mm, hatch_angle_deg, cross, fill, beam_mm, pen)``; ``modes``: the projection
    modes it may name."""
    path = Path(path)
    raw = read_json(path)
    check_header(path, raw, PROJECT_FORMAT, "an insitu project file", SCHEMA_VERSION)
    try:
        d = _Project.model_validate(raw)
    except ValidationError as e:
        raise FormatError(validation_message(path, e)) from None
    folder = path.parent
    if d.pens is None and d.default_pen is not None:
        raise FormatError(f"{path}: default_pen: {d.default_pen!r} given, but no pens")
    pens = None if d.pens is None else pen_table(d.pens, d.default_pen, path, "default_pen")
    placements = []
    for i, p in enumerate(d.placements):
        if p.mode not in modes:
            raise FormatError(f"{path}: placements[{i}].mode: expected {one_of(modes)}, "
                              f"got {p.mode!r}")
        names = (pens or DEFAULT_PENS).names
        if p.pen is not None and p.pen not in names:
            raise FormatError(f"{path}: placements[{i}].pen: expected {one_of(names)}, "
                              f"got {p.pen!r}")
        pattern = p.pattern if _SPEC.match(p.pattern) else str(
            _abs(p.pattern, folder, f"placements[{i}].pattern", path))
        placements.append(placement(pattern, tuple(p.at_mm), p.width_mm, p.rotate_deg, p.mode,
                                    p.hatch_mm, p.hatch_angle_deg, p.cross, p.fill,
                                    p.beam_mm, p.pen))
    return Project(
        rig=RigChoice(d.rig.workpiece, d.rig.seed, d.rig.binning,
                      _abs(d.rig.rig_file, folder, "rig.rig_file", path)),
        height_cal=_abs(d.calibration.height, folder, "calibration.height", path),
        field_correction=_abs(d.calibration.field, folder, "calibration.field", path),
        camera_cal=_abs(d.calibration.camera, folder, "calibration.camera", path),
        scan=ScanSettings(d.scan.region, d.scan.spacing_mm, d.scan.exposure_ms,
                          _abs(d.scan.replay, folder, "scan.replay", path), d.scan.speed_mm_s),
        cloud=_abs(d.cloud, folder, "cloud", path),
        placements=tuple(placements),
        selected=d.selected if -1 <= d.selected < len(placements) else -1,
        job=_abs(d.job, folder, "job", path, must_exist=False), pens=pens)
