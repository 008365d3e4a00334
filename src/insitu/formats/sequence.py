"""Recorded sequences (docs/formats.md, recorded sequence): a folder with ``sequence.json``
and ``frames/%05d.png``.

:class:`Sequence` reads one (validated, frames streamed one at a time); :class:`SequenceWriter`
records one atomically. Models keep fields they don't know (other tools may add some).
The optional ``ambient`` (docs/formats.md): a scan may hold one laser-off frame under the
room light, ``ambient.png``, named by the top-level ``"ambient": {"file", "exposure_ms"}``.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path, PurePosixPath
from typing import Annotated, Any, Literal

import cv2
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
from insitu.formats.atomic import atomic_folder, atomic_write_text
from insitu.formats.bounds import each_within, within
from insitu.formats.camera_spec import CameraSpec
from insitu.formats.images import check_bits, grey_image, read_image
from insitu.formats.limits import MAX_IMAGE_BYTES, check_file, check_inside
from insitu.formats.validation import (
    PositivePair,
    Range,
    Vec2,
    bad,
    dump_json,
    plain,
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


def _validate(model: type[BaseModel], data: Any, source: str, prefix: str = "") -> Any:
    try:
        return model.model_validate(data)
    except ValidationError as e:
        raise FormatError(validation_message(source, e, prefix)) from None


def _check_size(where: str, img: np.ndarray, cam: CameraSpec | None, shape=None) -> None:
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
        spec = _validate(SequenceSpec, data, str(path))
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
        _check_size(str(path), img, self.spec.camera)
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


class SequenceWriter:
    """Record a sequence into ``folder``, which appears complete at the end of the ``with``
    block (or not at all if anything raises). Images are written as they come, never held.

    ``scan_head``, ``camera``, ``checkerboard``: dicts or the models above; ``truth``: any
    JSON-able dict (numpy arrays and scalars allowed), written as ``truth.json``;
    ``pixel_bits``: the camera's significant bits (formats.md; None: the PNGs' depth).
    """

    def __init__(self, folder: str | Path, kind: str, scan_head: Any, camera: Any = None,
                 checkerboard: Any = None, truth: dict | None = None,
                 pixel_bits: int | None = None):
        self.folder = Path(folder)
        self._source = str(self.folder / "sequence.json")
        if kind not in KINDS:
            raise FormatError(f"{self._source}: kind: expected one of {', '.join(KINDS)}, "
                              f"got {kind!r}")
        if camera is None and kind != "camera-calibration":
            raise FormatError(f"{self._source}: camera: missing (required in a '{kind}' sequence)")
        self.kind = kind
        self._head, self._camera, self._board = plain(scan_head), plain(camera), plain(checkerboard)
        _validate(ScanHeadSpec, self._head, self._source, "scan_head")
        self._cam = None if camera is None else _validate(CameraSpec, self._camera, self._source,
                                                          "camera")
        if checkerboard is not None:
            _validate(CheckerboardSpec, self._board, self._source, "checkerboard")
        self._truth = None if truth is None else plain(truth)
        self._bits = pixel_bits
        self._frames: list[dict] = []
        self._ambient: dict | None = None
        self._laser_off: list[dict] = []
        self._size: tuple[int, ...] | None = None
        self._cm, self._tmp = None, None

    def __len__(self) -> int:
        return len(self._frames)

    def __enter__(self) -> "SequenceWriter":
        self._cm = atomic_folder(self.folder)
        self._tmp = self._cm.__enter__()
        try:
            (self._tmp / "frames").mkdir()
        except BaseException as e:
            self._cm.__exit__(type(e), e, e.__traceback__)
            raise
        return self

    def add(self, image: np.ndarray, **frame_fields: Any) -> int:
        """Write the next frame ((H, W) uint8/uint16) with its fields (line, spot, plate_z_mm,
        exposure_ms, ...); returns its index."""
        if self._tmp is None:
            raise RuntimeError("SequenceWriter.add() outside its 'with' block")
        i, where = len(self._frames), f"{self._source}: frames[{len(self._frames)}]"
        self._check_image(image, where)
        frame = {"file": FRAME_NAME.format(i), **plain(frame_fields)}
        spec = _validate(FrameSpec, frame, self._source, f"frames[{i}]")
        problems = frame_problems(self.kind, spec)
        if problems:
            raise FormatError(f"{where}.{problems[0][0]}: {problems[0][1]}")
        self._write_png(frame["file"], image, where)
        self._frames.append(frame)
        return i

    def add_ambient(self, image: np.ndarray, exposure_ms: float | None = None,
                    packed: bool = False) -> None:
        """Write the laser-off frame under the room light ((H, W) uint8/uint16, the frames'
        size) as ``ambient.png``, taken with ``exposure_ms``; ``packed``: one of the
        ``laser_off`` frames of the packed frames' exposures instead (``laser-off-N.png``)."""
        if self._tmp is None:
            raise RuntimeError("SequenceWriter.add_ambient() outside its 'with' block")
        where = f"{self._source}: ambient"
        self._check_image(image, where)
        name = f"laser-off-{len(self._laser_off)}.png" if packed else AMBIENT_NAME
        spec = _validate(AmbientSpec, plain({"file": name, "exposure_ms": exposure_ms}),
                         self._source, "laser_off" if packed else "ambient")
        self._write_png(name, image, where)
        spec = spec.model_dump(mode="json", exclude_none=True)
        if packed:
            self._laser_off.append(spec)
        else:
            self._ambient = spec

    def _check_image(self, image: np.ndarray, where: str) -> None:
        if (not isinstance(image, np.ndarray) or image.ndim != 2
                or image.dtype not in (np.uint8, np.uint16)):
            got = (f"{image.dtype} {image.shape}" if isinstance(image, np.ndarray)
                   else type(image).__name__)
            raise FormatError(f"{where}: expected a (H, W) uint8 or uint16 image, got {got}")
        _check_size(where, image, self._cam, self._size)
        check_bits(where, image, self._bits)
        self._size = image.shape

    def _write_png(self, name: str, image: np.ndarray, where: str) -> None:
        ok, buf = cv2.imencode(".png", image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise FormatError(f"{where}: OpenCV could not encode the image as PNG")
        with open(self._tmp / name, "wb") as f:
            f.write(buf.tobytes())
            f.flush()
            os.fsync(f.fileno())

    def _finish(self) -> None:
        data = {"format": FORMAT, "kind": self.kind, "camera": self._camera,
                "scan_head": self._head, "frames": self._frames, "checkerboard": self._board,
                "ambient": self._ambient, "laser_off": self._laser_off or None,
                "pixel_bits": self._bits}
        spec = _validate(SequenceSpec, data, self._source)
        atomic_write_text(self._tmp / "sequence.json",
                          dump_json(spec.model_dump(mode="json", exclude_none=True)))
        if self._truth is not None:
            try:
                truth = dump_json(self._truth)
            except (TypeError, ValueError) as e:
                raise FormatError(f"{self.folder / 'truth.json'}: cannot be written as JSON "
                                  f"({e})") from e
            atomic_write_text(self._tmp / "truth.json", truth)

    def __exit__(self, exc_type, exc, tb) -> bool:
        cm, self._cm = self._cm, None
        try:
            if exc_type is None:
                try:
                    self._finish()
                except BaseException as e:
                    cm.__exit__(type(e), e, e.__traceback__)
                    raise
                cm.__exit__(None, None, None)
            else:
                cm.__exit__(exc_type, exc, tb)
        finally:
            self._tmp = None
        return False
