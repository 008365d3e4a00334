"""What insitu needs of a camera, a scan head and a stage. Units at this boundary: mm, ms.

Backends (sim, replay, real) implement these; the backend is chosen by configuration.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from insitu.geometry import field


@runtime_checkable
class Camera(Protocol):
    width: int
    height: int

    def set_exposure(self, exposure_ms: float) -> None: ...

    def grab(self, timeout_s: float = 5.0) -> np.ndarray:
        """One frame, (height, width) uint8 or uint16. Raises DeviceError on timeout."""
        ...


@runtime_checkable
class ExposureCamera(Camera, Protocol):
    """A camera that says the exposure its frames are taken with (a recording's does not)."""

    exposure_ms: float


@runtime_checkable
class RoiCamera(Camera, Protocol):
    """A camera that reads out only a region of interest (faster frames)."""

    def set_region_of_interest(self, roi: tuple[int, int, int, int] | None) -> None:
        """Read only the pixels u0 ≤ u < u1, v0 ≤ v < v1 of ``roi`` = (u0, v0, u1, v1)
        (widened to the sensor's steps; None: the whole frame); the frames keep their size,
        0 outside it."""
        ...


@runtime_checkable
class BitDepthCamera(Camera, Protocol):
    """A camera whose frames hold fewer significant bits than their words (a GenICam Mono10 or
    Mono12 camera delivers 0 … 1023 or 0 … 4095 in uint16)."""

    pixel_bits: int


def pixel_bits_of(camera: Camera) -> int | None:
    """The camera's significant bits (docs/formats.md ``pixel_bits``; None: its frames' own
    depth)."""
    return camera.pixel_bits if isinstance(camera, BitDepthCamera) else None


def check_in_field(field_size_mm, *points) -> None:
    """What a scan head does before it draws: SafetyError naming the first of ``points``
    ((2,) mm on z = 0 each) outside the field ``field_size_mm`` (width, height) centred on the
    origin (:func:`insitu.geometry.field.check_in_field`)."""
    pts = np.array(points, float).reshape(-1, 2)
    field.check_in_field(pts, field_size_mm, lambda i, size: f"scan head: point "
                         f"{list(map(float, pts[i]))} mm is outside the field {size}")


@runtime_checkable
class ScanHead(Protocol):
    field_size_mm: tuple[float, float]
    z_range_mm: tuple[float, float]

    def set_line_speed(self, speed_mm_s: float) -> None:
        """How fast :meth:`show_line` sweeps the line, mm/s."""
        ...

    def show_line(self, start: np.ndarray, end: np.ndarray, focus_z: float = 0.0) -> None:
        """Draw the line start → end (mm on z = 0) repeatedly at pilot power until changed."""
        ...

    def show_lines(self, lines, focus_z: float = 0.0) -> None:
        """Draw the ``lines`` ((start, end) mm on z = 0 each) in turn, repeatedly, one list
        (the camera triggered at its start): several lines in one exposure."""
        ...

    def show_spot(self, xy: np.ndarray, focus_z: float = 0.0) -> None:
        """Hold the pilot laser on the point xy (mm on z = 0)."""
        ...

    def off(self) -> None:
        """Laser off, at once. Never raises."""
        ...


@runtime_checkable
class Stage(Protocol):
    def move_z(self, z_mm: float) -> None:
        """Move to the height z (mm, world frame) and wait until there."""
        ...

    def position_z(self) -> float: ...
