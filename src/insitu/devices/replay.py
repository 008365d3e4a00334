"""Replay backend: a camera that serves the frames of a recorded sequence, in order."""

from __future__ import annotations

import numpy as np

from insitu.errors import DeviceError
from insitu.formats.sequence import FrameSpec, Sequence


class ReplayCamera:
    """Frames of ``sequence`` one by one; :attr:`current` is the spec of the last frame served."""

    def __init__(self, sequence: Sequence):
        self.sequence = sequence
        cam = sequence.camera
        self.width = cam.width if cam else 0
        self.height = cam.height if cam else 0
        self.index = 0
        self.current: FrameSpec | None = None

    def set_exposure(self, exposure_ms: float) -> None:
        """Recorded frames keep their exposure."""

    def grab(self, timeout_s: float = 5.0) -> np.ndarray:
        if self.index >= len(self.sequence):
            raise DeviceError(f"replay camera: {self.sequence.folder} has no frame "
                              f"{self.index} (it holds {len(self.sequence)})")
        self.current = self.sequence.frames[self.index]
        frame = self.sequence.read_frame(self.index)
        self.index += 1
        return frame
