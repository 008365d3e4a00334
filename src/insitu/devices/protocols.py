"""What insitu needs of a camera, a scan head and a stage. Units at this boundary: mm, ms.

Backends (sim, replay, real) implement these; the backend is chosen by configuration.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from insitu.errors import SafetyError


@runtime_checkable
class Camera(Protocol):
    width: int
    height: int

    def set_exposure(self, exposure_ms: float) -> None: ...

    def grab(self, timeout_s: float = 5.0) -> np.ndarray:
        """One frame, (height, width) uint8 or uint16. Raises DeviceError on timeout."""
        ...


def check_in_field(field_size_mm, *points) -> None:
    """SafetyError naming the first point (x, y mm on z = 0) outside the field, centred on
    the origin, of ``field_size_mm`` (width, height)."""
    half = np.asarray(field_size_mm, float) / 2
    for p in points:
        if np.any(np.abs(np.asarray(p, float)) > half + 1e-9):
            raise SafetyError(f"scan head: point {list(map(float, p))} mm is outside the "
                              f"field ±{half[0]:g} × ±{half[1]:g} mm")


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
