"""Record a sequence (docs/formats.md, recorded sequence) atomically: :class:`SequenceWriter`
writes each frame as it comes and makes the folder appear complete, validated as
:class:`~insitu.formats.sequence.Sequence` reads it, or not at all."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_folder, atomic_write_text
from insitu.formats.camera_spec import CameraSpec
from insitu.formats.images import check_bits
from insitu.formats.sequence import (
    AMBIENT_NAME,
    FORMAT,
    FRAME_NAME,
    KINDS,
    AmbientSpec,
    CheckerboardSpec,
    FrameSpec,
    ScanHeadSpec,
    SequenceSpec,
    check_frame_size,
    frame_problems,
    validate_as,
)
from insitu.formats.validation import dump_json, plain


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
        validate_as(ScanHeadSpec, self._head, self._source, "scan_head")
        self._cam = None if camera is None else validate_as(CameraSpec, self._camera, self._source,
                                                          "camera")
        if checkerboard is not None:
            validate_as(CheckerboardSpec, self._board, self._source, "checkerboard")
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
        spec = validate_as(FrameSpec, frame, self._source, f"frames[{i}]")
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
        spec = validate_as(AmbientSpec, plain({"file": name, "exposure_ms": exposure_ms}),
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
        check_frame_size(where, image, self._cam, self._size)
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
        spec = validate_as(SequenceSpec, data, self._source)
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
