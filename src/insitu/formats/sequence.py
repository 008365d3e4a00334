"""Recorded sequences (docs/formats.md, recorded sequence): a folder with ``sequence.json``
and ``frames/%05d.png``.

:class:`Sequence` reads one (validated, frames streamed one at a time);
:class:`~insitu.formats.sequence_writer.SequenceWriter` records one atomically. Models keep fields
they don't know (other tools may add some). The optional ``ambient`` (docs/formats.md): a scan may
hold one laser-off frame under the room light, ``ambient.png``, named by the top-level ``"ambient":
{"file", "exposure_ms"}``.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path, PurePosixPath
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from insitu.errors import FormatError
from insitu.formats.bounds import each_within, within
from insitu.formats.camera_spec import CameraSpec
from insitu.formats.images import check_bits, grey_image, read_image
from insitu.formats.limits import MAX_IMAGE_BYTES, check_file, check_inside
from insitu.formats.validation import (
    PositivePair,
    Range,
    Vec2,
    bad,
    read_json,
    show,
    validation_message,
)

FORMAT = "insitu-sequence/1"
Kind = Literal["scan", "height-calibration", "field-calibration", "camera-calibration"]
KINDS: tuple[str, ...] = Kind.__args__
FRAME_NAME = "frames/{:05d}.png"
AMBIENT_NAME = "ambient.png"
_CONFIG = ConfigDict(extra="allow", allow_inf_nan=False)
Pivot, Position = within("pivot_height_mm"), within("position_mm")
Corners, Square = within("board_corners", int), within("length_mm")
Exposure, Point = within("exposure_ms"), Annotated[Vec2, each_within("position_mm")]
class ScanHeadSpec(BaseModel):
    """Nominal scan-head geometry: beam pivot height H above z = 0, usable field, focus range (mm)."""

    model_config = _CONFIG
    lens: Literal["non-telecentric", "telecentric"]
    pivot_height_mm: Pivot
    field_size_mm: Annotated[PositivePair, each_within("field_size_mm")]
    z_range_mm: Annotated[Range, each_within("position_mm")]


class LineSpec(BaseModel):
    """A line commanded on the nominal plane z = 0, from ``start`` [x1, y1] to ``end`` (mm)."""

    model_config = _CONFIG
    start: Annotated[Vec2, each_within("position_mm")]
    end: Annotated[Vec2, each_within("position_mm")]

    @model_validator(mode="after")
    def _not_a_point(self) -> "LineSpec":
        if self.start == self.end:
            raise bad(f"expected start != end, got both {show(self.start)}")
        return self


def _relative_file(f: str) -> str:
    p = PurePosixPath(f.replace("\\", "/"))
    if not f or "\x00" in f or p.is_absolute() or ".." in p.parts or ":" in f[:2]:
        raise bad("expected a path relative to the sequence folder", f)
    return f


RelativeFile = Annotated[str, AfterValidator(_relative_file)]


class AmbientSpec(BaseModel):
    """Our optional extension: one frame with the laser off under the room light, taken
    before the lines (``file`` relative to the folder, ``exposure_ms`` it was taken with)."""

    model_config = _CONFIG
    file: RelativeFile
    exposure_ms: Exposure | None = None


class FrameSpec(BaseModel):
    """One frame: image ``file`` (relative to the folder) and what the head showed (mm): a
    ``line``, or ``lines`` drawn in one exposure (never both; one entry is read as ``line``).
    ``survey`` (ours): a frame that bounded the heights before lines were packed
    (:mod:`insitu.reconstruct.packing`), its lines measured again later."""

    model_config = _CONFIG
    file: RelativeFile
    line: LineSpec | None = None
    lines: Annotated[list[LineSpec], Field(min_length=1)] | None = None
    survey: bool = False
    spot: Point | None = None
    fiducials: Annotated[list[Point], Field(min_length=1)] | None = None
    fiducial_diameter_mm: Square | None = None
    plate_z_mm: Position | None = None
    exposure_ms: Exposure | None = None

    @model_validator(mode="after")
    def _line_or_lines(self) -> "FrameSpec":
        if self.line is not None and self.lines is not None:
            raise bad("expected 'line' or 'lines', not both", at="lines")
        if self.lines is not None and len(self.lines) == 1:
            self.line, self.lines = self.lines[0], None
        return self

    def drawn(self) -> list[tuple[list[float], list[float]]]:
        """The lines the head drew in this frame, (start, end) mm each (empty: none)."""
        return [(list(s.start), list(s.end))
                for s in ([self.line] if self.line is not None else self.lines or [])]


class CheckerboardSpec(BaseModel):
    """Inner-corner counts (as OpenCV's patternSize) and square side, mm."""

    model_config = _CONFIG
    cols: Corners
    rows: Corners
    square_mm: Square


def frame_problems(kind: str, frame: FrameSpec) -> list[tuple[str, str]]:
    """(field, message) for each per-kind rule of docs/formats.md that ``frame`` breaks."""
    need = {"scan": ("line",), "height-calibration": ("line", "plate_z_mm"),
            "field-calibration": ("spot", "plate_z_mm")}.get(kind, ())
    if kind == "field-calibration" and frame.fiducials is not None:    # marked circles
        need = ("fiducials", "fiducial_diameter_mm", "plate_z_mm")
    if frame.lines is not None and kind not in ("scan", "height-calibration"):
        return [("lines", f"several lines in one frame: not in a '{kind}' sequence")]
    return [(name, f"missing (required in a '{kind}' sequence)") for name in need
            if getattr(frame, name) is None and not (name == "line" and frame.lines)]


class SequenceSpec(BaseModel):
    """The content of ``sequence.json``."""

    model_config = _CONFIG
    format: Literal["insitu-sequence/1"]
    kind: Kind
    camera: CameraSpec | None = None
    scan_head: ScanHeadSpec
    frames: list[FrameSpec]
    checkerboard: CheckerboardSpec | None = None
    ambient: AmbientSpec | None = None
    laser_off: list[AmbientSpec] | None = None
    pixel_bits: Literal[8, 10, 12, 14, 16] | None = None

    @field_validator("frames", mode="before")
    @classmethod
    def _some_frames(cls, v: Any) -> Any:
        if isinstance(v, list) and not v:
            raise bad("expected at least one frame", v)
        return v

    @model_validator(mode="after")
    def _per_kind(self) -> "SequenceSpec":
        if self.camera is None and self.kind != "camera-calibration":
            raise bad(f"missing (required in a '{self.kind}' sequence)", at="camera")
        if self.checkerboard is None and self.kind == "camera-calibration":
            raise bad("missing (required in a 'camera-calibration' sequence)", at="checkerboard")
        problems = [(f"frames[{i}].{name}", msg) for i, f in enumerate(self.frames)
                    for name, msg in frame_problems(self.kind, f)]
        if problems:
            raise bad(problems[0][1], at=problems[0][0], more=len(problems) - 1)
        return self


def validate_as(model: type[BaseModel], data: Any, source: str, prefix: str = "") -> Any:
    """``data`` validated as ``model``; a FormatError naming ``source`` and the field if not."""
    try:
        return model.model_validate(data)
    except ValidationError as e:
        raise FormatError(validation_message(source, e, prefix)) from None


def check_frame_size(where: str, img: np.ndarray, cam: CameraSpec | None, shape=None) -> None:
    """FormatError unless ``img`` is camera width x height (or ``shape`` if no camera)."""
    expect, whose = ((cam.height, cam.width), "camera is") if cam else (shape, "earlier frames are")
    if expect is not None and img.shape != tuple(expect):
        raise FormatError(f"{where}: image is {img.shape[1]}x{img.shape[0]} pixels, {whose} "
                          f"{expect[1]}x{expect[0]} (width x height)")


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except (OSError, ValueError):
        return False


class Sequence:
    """A recorded sequence folder. Frames are read from disk on demand, one at a time."""

    def __init__(self, folder: Path, spec: SequenceSpec):
        self.folder, self.spec = Path(folder), spec

    @classmethod
    def open(cls, folder: str | Path) -> "Sequence":
        """Validate ``folder/sequence.json`` and check that every frame file exists."""
        folder = Path(folder)
        if not folder.is_dir():
            raise FormatError(f"{folder}: " + ("not a folder" if folder.exists()
                                               else "no such sequence folder"))
        path = folder / "sequence.json"
        if path.exists():
            check_inside(path, folder, "sequence file")
        data = read_json(path, missing="missing (a recorded sequence folder holds sequence.json)")
        spec = validate_as(SequenceSpec, data, str(path))
        missing = [f.file for f in spec.frames if not _exists(folder / f.file)]
        if missing:
            raise FormatError(f"{folder}: frame file {missing[0]} is missing ({len(missing)} of "
                              f"{len(spec.frames)} frame files missing)")
        for f in spec.frames:
            check_inside(folder / f.file, folder, "frame file")
            check_file(folder / f.file, MAX_IMAGE_BYTES, "frame image")
        for extra in [spec.ambient] * (spec.ambient is not None) + (spec.laser_off or []):
            ambient = folder / extra.file
            check_inside(ambient, folder, "ambient frame file")
            check_file(ambient, MAX_IMAGE_BYTES, "ambient frame image",
                       missing="missing (sequence.json names it as a laser-off frame)")
        return cls(folder, spec)

    kind = property(lambda self: self.spec.kind)
    camera = property(lambda self: self.spec.camera)
    scan_head = property(lambda self: self.spec.scan_head)
    frames = property(lambda self: self.spec.frames)
    checkerboard = property(lambda self: self.spec.checkerboard)
    pixel_bits = property(lambda self: self.spec.pixel_bits)    # None: the PNGs' own depth

    def __len__(self) -> int:
        return len(self.spec.frames)

    def __repr__(self) -> str:
        return f"Sequence({str(self.folder)!r}, kind={self.kind!r}, frames={len(self)})"

    ambient = property(lambda self: self.spec.ambient,
                       doc="The laser-off frame's spec (our extension), None without one.")
    laser_off = property(lambda self: self.spec.laser_off or [],
                         doc="The laser-off frames of packed exposures (ours): their specs.")

    def read_laser_off(self, i: int) -> np.ndarray:
        """Laser-off frame ``i`` of :attr:`laser_off`, (H, W) as the frames."""
        return self._read_grey(self.folder / self.laser_off[i].file, "ambient frame file")

    def read_frame(self, i: int) -> np.ndarray:
        """Frame ``i`` as (H, W) uint8 or uint16; FormatError naming the file if it is not one."""
        return self._read_grey(self.folder / self.spec.frames[i].file, "frame file")

    def read_ambient(self) -> np.ndarray | None:
        """The laser-off frame under the room light (H, W) uint8 or uint16, None when the
        recording has none (other recorders' never do)."""
        if self.spec.ambient is None:
            return None
        return self._read_grey(self.folder / self.spec.ambient.file, "ambient frame file")

    def _read_grey(self, path: Path, what: str) -> np.ndarray:
        cam = self.spec.camera
        check_inside(path, self.folder, what)
        img = read_image(path, expect=None if cam is None else (cam.width, cam.height),
                         expected="camera is")
        img = grey_image(path, img)
        check_frame_size(str(path), img, self.spec.camera)
        check_bits(str(path), img, self.spec.pixel_bits)
        return img

    def __iter__(self) -> Iterator[tuple[int, FrameSpec, np.ndarray]]:
        """(index, frame spec, image) in acquisition order, one image in memory at a time."""
        for i, frame in enumerate(self.spec.frames):
            yield i, frame, self.read_frame(i)

    @property
    def has_truth(self) -> bool:
        return (self.folder / "truth.json").is_file()

    def read_truth(self) -> dict:
        """The simulator's ``truth.json``. Only tests and benchmarks may read it, to score a
        result; the software never measures with it."""
        path = self.folder / "truth.json"
        data = read_json(path, missing="no truth.json (only simulated sequences have one)")
        if not isinstance(data, dict):
            raise FormatError(f"{path}: expected a JSON object, got {type(data).__name__}")
        return data
