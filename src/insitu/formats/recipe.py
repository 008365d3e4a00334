"""The production recipe: what to mark on every part of a run, in the part's own frame.

    {"format": "insitu-recipe/1", "schema_version": 1, "saved": "...Z",
     "reference": {"mesh": "part.stl"},            # or {"cloud": "first-scan.ply",
                                                   #     "room_light": "first-room.png"}
     "workpiece": "step-block",                    # the simulated rig's part (optional)
     "placements": [{"pattern": "qr:\\"{serial:05d}\\"", "at_mm": [0, 20], "width_mm": 8,
                     ...}],                        # the project file's placements, part frame
     "laser": {"power_pct": 30, "frequency_khz": 20, "mark_speed_mm_s": 500,
               "jump_speed_mm_s": 3000},
     "scan": {"region": null, "margin_mm": 5, "spacing_mm": 0.25, "exposure_ms": 10,
              "speed_mm_s": 2000,                   # region: world (x0, x1, y0, y1) mm
              "cross": true, "cross_spacing_mm": 0.5,   # a crossed pass (absent: none)
              "second_look": true,                 # along y only: crossed when unheld
              "lines_per_frame": "auto",           # K or "auto" a frame (absent: one)
              "survey_mm": 4},                     # a first pass finds the part (absent: none)
     "locate": {"prefer_angle_deg": null,          # which of a symmetric part's turns
                "tolerance_mm": 0.05, "turn_bound_deg": 0.1,   # 2σ at its rim, 3σ of its turn
                "turn_tolerance_deg": null},       # 2σ of its turn (absent, null: none)
     "read": {"offset_tolerance_mm": 0.1},         # a mark read back farther: part failed
     "serial": {"counter": "serial.counter.json", "start": 1, "fields": {}}}

Paths are relative to the recipe's folder. The reference defines the part's frame: a mesh in
it, or the cloud of a first scan (its world frame is then the part's) with, optionally, the
room-light frame that scan took (its outline is fitted there). ``locate.tolerance_mm``,
``turn_bound_deg``: a part is marked only when its pose is known to 2σ within the first at
its rim and its turn to 3σ within the second (absent: 0.05 mm, 0.1°), and, when set, to 2σ
within ``turn_tolerance_deg`` (the marks' own angle tolerance; absent or null: none).
``read.offset_tolerance_mm``: a marked part whose marks are read back farther than this from
their planned place is logged with that reason (absent: 0.1 mm). ``scan.region`` null:
where the part lies, grown by ``margin_mm`` (the simulated rig knows where; a real rig needs
the region). ``scan.cross``: a second, crossed pass (lines at 45° to x, ``cross_spacing_mm``
apart, null: ``spacing_mm``), so every edge of the part is crossed by some line whatever its
turn; absent (older recipes): along y only; ``insitu recipe new`` turns it on.
``scan.second_look`` (default on): a scan along y only whose lines run along the part's
edges, so that they leave its pose unheld, is followed by a crossed scan over where the part
lies, and the part is located on that. ``scan.survey_mm``: a first pass of lines this far
apart finds the part and the heights it spans; the scan's lines then sweep only over the
part and its margin, searched at those heights (:mod:`insitu.services.survey`; absent: the
whole region). ``serial.start`` creates the counter when it does not exist yet.
"""

from __future__ import annotations

from collections.abc import Callable, Collection
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError, model_validator

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.bounds import each_within, within
from insitu.formats.counter import Serial
from insitu.formats.mesh import MESH_SUFFIXES, is_mesh_file
from insitu.formats.project import (
    _SPEC,
    Exposure,
    Length,
    Region,
    Spacing,
    Speed,
    _abs,
    _Placement,
    _rel,
    _Strict,
    check_header,
)
from insitu.formats.validation import dump_json, one_of, read_json, validation_message

RECIPE_FORMAT = "insitu-recipe/1"
SCHEMA_VERSION = 1
COUNTER = "serial.counter.json"


class _Reference(_Strict):
    mesh: str | None = None
    cloud: str | None = None
    room_light: str | None = None

    @model_validator(mode="after")
    def _one(self):
        if (self.mesh is None) == (self.cloud is None):
            raise ValueError("expected exactly one of mesh, cloud")
        return self


class _Laser(_Strict):
    power_pct: within("power_pct") = 30.0
    frequency_khz: within("frequency_khz") = 20.0
    mark_speed_mm_s: within("mark_speed_mm_s") = 500.0
    jump_speed_mm_s: within("jump_speed_mm_s") = 3000.0


class _Scan(_Strict):
    region: Region | None = None
    margin_mm: Length = 5.0
    spacing_mm: Spacing = 0.25
    exposure_ms: Exposure = 10.0
    speed_mm_s: Speed = 2000.0
    cross: bool = False
    cross_spacing_mm: Spacing | None = None
    second_look: bool = True
    lines_per_frame: Annotated[int, Field(ge=1)] | Literal["auto"] | None = None
    survey_mm: Spacing | None = None


class _Locate(_Strict):
    prefer_angle_deg: Annotated[tuple[float, float], each_within("angle_deg")] | None = None
    tolerance_mm: within("tolerance_mm") = 0.05
    turn_bound_deg: within("turn_bound_deg") = 0.1
    turn_tolerance_deg: within("turn_bound_deg") | None = None


class _Read(_Strict):
    offset_tolerance_mm: within("tolerance_mm") = 0.1


class _Serial(_Strict):
    counter: str = COUNTER
    start: Serial | None = None
    fields: dict[str, str] = {}


class _Recipe(_Strict):
    format: Literal["insitu-recipe/1"]
    schema_version: int = Field(ge=1)
    saved: str | None = None
    reference: _Reference
    workpiece: str | None = None
    placements: list[_Placement] = Field(min_length=1)
    laser: _Laser = _Laser()
    scan: _Scan = _Scan()
    locate: _Locate = _Locate()
    read: _Read = _Read()
    serial: _Serial = _Serial()


@dataclass(frozen=True)
class RecipeScan:
    """Where and how each part is scanned: ``region`` world (x0, x1, y0, y1) mm (None:
    where the part lies, grown by ``margin_mm``), line ``spacing_mm``, camera
    ``exposure_ms``, line sweep ``speed_mm_s``; ``cross``: a second, crossed pass
    ``cross_spacing_mm`` apart (None: ``spacing_mm``); off unless asked, as in files without
    it (``insitu recipe new`` asks for it by default); ``second_look``: without ``cross``,
    scan crossed over the part when the lines along y leave its pose unheld;
    ``lines_per_frame``: K or "auto", several lines per exposure
    (:mod:`insitu.reconstruct.packing`; None: one); ``survey_mm``: a first pass of lines this
    far apart bounds where the part lies and its heights (None: the whole region)."""

    region: tuple[float, float, float, float] | None = None
    margin_mm: float = 5.0
    spacing_mm: float = 0.25
    exposure_ms: float = 10.0
    speed_mm_s: float = 2000.0
    cross: bool = False
    cross_spacing_mm: float | None = None
    second_look: bool = True
    lines_per_frame: int | str | None = None
    survey_mm: float | None = None


@dataclass(frozen=True)
class Recipe:
    """A recipe in memory, every path absolute. ``reference``: the mesh or cloud file
    (``reference_kind`` "mesh" | "cloud") whose frame is the part's; ``placements``: the
    caller's placement dataclasses, part frame; ``laser``: the job's laser parameters
    (LaserParams fields); ``prefer_angle_deg``: (lo, hi) degrees, the turn about z to keep
    of a symmetric part's (None: refuse an ambiguous one); ``counter``: the serial counter,
    created with first serial ``serial_start`` when missing; ``fields``: values of the
    texts' own fields; ``workpiece``: the simulated rig's part (None: its default);
    ``reference_room_light``: a cloud reference's room-light frame, its outline fitted there
    (None: none); ``tolerance``: (mm, degrees) a located pose's 2σ at the part's rim and 3σ
    of its turn must lie within; ``read_tolerance_mm``: how far from its planned place a
    mark may be read back before the part is failed."""

    reference: Path
    reference_kind: str
    placements: tuple[Any, ...]
    laser: dict[str, float] = field(default_factory=lambda: _Laser().model_dump())
    scan: RecipeScan = RecipeScan()
    prefer_angle_deg: tuple[float, float] | None = None
    counter: Path | None = None
    serial_start: int | None = None
    fields: dict[str, str] = field(default_factory=dict)
    workpiece: str | None = None
    reference_room_light: Path | None = None
    tolerance: tuple[float, float] = (0.05, 0.1)
    turn_tolerance_deg: float | None = None
    read_tolerance_mm: float = 0.1


def reference_kind(path: str | Path) -> str:
    """"mesh" (STL, OBJ, a PLY with faces) or "cloud" (a scan's .ply); FormatError for
    another suffix."""
    path = Path(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise FormatError(f"{path}: expected a mesh ({', '.join(MESH_SUFFIXES)}) or a scan's "
                          "cloud (.ply)")
    return "mesh" if is_mesh_file(path) else "cloud"


def recipe_json(recipe: Recipe, path: Path) -> str:
    """The text of the recipe file at ``path`` (paths relative to its folder)."""
    folder = Path(path).parent
    placements = []
    for p in recipe.placements:
        d = asdict(p)
        d["pattern"] = p.pattern if _SPEC.match(p.pattern) else _rel(Path(p.pattern), folder)
        placements.append(d)
    s = recipe.scan
    counter = recipe.counter if recipe.counter is not None else folder / COUNTER
    data = _Recipe(
        format=RECIPE_FORMAT, schema_version=SCHEMA_VERSION,
        saved=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        reference={recipe.reference_kind: _rel(recipe.reference, folder),
                   "room_light": (None if recipe.reference_room_light is None else
                                  _rel(recipe.reference_room_light, folder))},
        workpiece=recipe.workpiece, placements=placements, laser=_Laser(**recipe.laser),
        scan=_Scan(region=s.region, margin_mm=s.margin_mm, spacing_mm=s.spacing_mm,
                   exposure_ms=s.exposure_ms, speed_mm_s=s.speed_mm_s, cross=s.cross,
                   cross_spacing_mm=s.cross_spacing_mm, second_look=s.second_look,
                   lines_per_frame=s.lines_per_frame, survey_mm=s.survey_mm),
        locate=_Locate(prefer_angle_deg=recipe.prefer_angle_deg,
                       tolerance_mm=recipe.tolerance[0], turn_bound_deg=recipe.tolerance[1],
                       turn_tolerance_deg=recipe.turn_tolerance_deg),
        read=_Read(offset_tolerance_mm=recipe.read_tolerance_mm),
        serial=_Serial(counter=_rel(counter, folder), start=recipe.serial_start,
                       fields=dict(recipe.fields)))
    out = data.model_dump(mode="json")
    out["reference"] = {k: v for k, v in out["reference"].items() if v is not None}
    return dump_json(out) + "\n"


def write_recipe(path: str | Path, recipe: Recipe) -> None:
    """Write the recipe atomically."""
    path = Path(path)
    atomic_write_text(path, recipe_json(recipe, path))


def read_recipe(path: str | Path, placement: Callable[..., Any],
                modes: Collection[str]) -> Recipe:
    """Read and validate a recipe; FormatError naming the file and the field. Placements are
    made by ``placement(pattern, at_mm, width_mm, rotate_deg, mode, hatch_mm,
    hatch_angle_deg, cross, fill, beam_mm, pen)``; ``modes``: the projection modes they may name."""
    path = Path(path)
    raw = read_json(path)
    check_header(path, raw, RECIPE_FORMAT, "an insitu recipe", SCHEMA_VERSION)
    try:
        d = _Recipe.model_validate(raw)
    except ValidationError as e:
        raise FormatError(validation_message(path, e)) from None
    folder = path.parent
    placements = []
    for i, p in enumerate(d.placements):
        if p.mode not in modes:
            raise FormatError(f"{path}: placements[{i}].mode: expected {one_of(modes)}, "
                              f"got {p.mode!r}")
        pattern = p.pattern if _SPEC.match(p.pattern) else str(
            _abs(p.pattern, folder, f"placements[{i}].pattern", path))
        placements.append(placement(pattern, tuple(p.at_mm), p.width_mm, p.rotate_deg, p.mode,
                                    p.hatch_mm, p.hatch_angle_deg, p.cross, p.fill,
                                    p.beam_mm, p.pen))
    kind = "mesh" if d.reference.mesh is not None else "cloud"
    s = d.scan
    return Recipe(
        reference=_abs(getattr(d.reference, kind), folder, f"reference.{kind}", path),
        reference_kind=kind, placements=tuple(placements), laser=d.laser.model_dump(),
        scan=RecipeScan(s.region, s.margin_mm, s.spacing_mm, s.exposure_ms, s.speed_mm_s,
                        s.cross, s.cross_spacing_mm, s.second_look, s.lines_per_frame,
                        s.survey_mm),
        prefer_angle_deg=d.locate.prefer_angle_deg,
        counter=_abs(d.serial.counter, folder, "serial.counter", path, must_exist=False),
        serial_start=d.serial.start, fields=dict(d.serial.fields), workpiece=d.workpiece,
        reference_room_light=(None if d.reference.room_light is None else _abs(
            d.reference.room_light, folder, "reference.room_light", path)),
        tolerance=(d.locate.tolerance_mm, d.locate.turn_bound_deg),
        turn_tolerance_deg=d.locate.turn_tolerance_deg,
        read_tolerance_mm=d.read.offset_tolerance_mm)
