"""UVC / USB cameras (and video files, image sequences, streams) through OpenCV VideoCapture.

``source``: a device index (``0``), a device path (``/dev/video2``), a video file or URL, or an
image-sequence pattern (``frames/%04d.png``). Frames are returned single-channel (colour
converted to gray), uint8 or uint16 as the source gives them. VideoCapture has no timeout of
its own, so opening and every grab run on one reader thread that the caller waits for: a
camera that stops delivering raises DeviceError after ``timeout_s`` and the camera is then
broken (the stuck read is abandoned; reopen it).

Exposure: OpenCV's V4L2 backend takes UVC exposure in 100 µs units with manual exposure
selected (CAP_PROP_AUTO_EXPOSURE = 1); DirectShow takes log2(seconds). Gain is in the
camera's own units.
"""

from __future__ import annotations

import math
import queue
import sys
import threading
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

from insitu.errors import ConfigError, DeviceError
from insitu.formats.bounds import check


class _Reader:
    """Runs calls on one thread, so that a call that never returns leaves the caller free."""

    def __init__(self, name: str):
        self._jobs: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()
        self.stuck = False

    def _run(self) -> None:
        while True:
            fn, box, done = self._jobs.get()
            if fn is None:
                return
            try:
                box.append((True, fn()))
            except BaseException as e:                 # noqa: BLE001 — handed to the caller
                box.append((False, e))
            done.set()

    def call(self, fn: Callable[[], Any], timeout_s: float, what: str) -> Any:
        if self.stuck:
            raise DeviceError(f"{what}: the camera stopped answering earlier; reopen it")
        box: list = []
        done = threading.Event()
        self._jobs.put((fn, box, done))
        if not done.wait(timeout_s):
            self.stuck = True
            raise DeviceError(f"{what}: no answer within {timeout_s:g} s (camera unplugged "
                              "or not delivering frames)")
        ok, value = box[0]
        if not ok:
            raise value
        return value

    def stop(self) -> None:
        self._jobs.put((None, None, None))


def _exposure_value(exposure_ms: float, backend: str) -> float:
    if backend == "DSHOW":
        return math.log2(exposure_ms / 1000.0)
    return exposure_ms * 10.0                          # V4L2 and most others: 100 µs units


class OpenCVCamera:
    """A :class:`~insitu.devices.protocols.Camera`. ``resolution``: (width, height) px to ask
    for (None: the camera's default); DeviceError if the camera gives another."""

    def __init__(self, source: int | str, resolution: tuple[int, int] | None = None,
                 exposure_ms: float | None = None, gain: float | None = None,
                 timeout_s: float = 5.0):
        for key, bound, value in (("exposure_ms", "exposure_ms", exposure_ms),
                                  ("timeout_s", "timeout_s", timeout_s),
                                  *(("resolution", "image_px", v) for v in resolution or ())):
            if value is not None:
                check(bound, value, f"options.camera.{key}", ConfigError)
        self.source, self.timeout_s = source, float(timeout_s)
        self.name = f"OpenCV camera {source!r}"
        self._reader = _Reader(self.name)
        sequence = isinstance(source, str) and "%" in source
        device = isinstance(source, int) or str(source).startswith("/dev/video")
        api = (cv2.CAP_IMAGES if sequence else
               cv2.CAP_V4L2 if device and sys.platform.startswith("linux") else cv2.CAP_ANY)
        self.cap = self._reader.call(lambda: cv2.VideoCapture(source, api), self.timeout_s,
                                     f"{self.name}: open")
        if not self.cap.isOpened():
            raise DeviceError(f"{self.name}: cannot open it (no such device or file, or it is "
                              "in use by another program)")
        self.backend = self.cap.getBackendName()
        if resolution is not None:
            self._set(cv2.CAP_PROP_FRAME_WIDTH, resolution[0], "width")
            self._set(cv2.CAP_PROP_FRAME_HEIGHT, resolution[1], "height")
        if sequence:                                   # 16-bit images stay 16-bit
            self.cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        self.width = int(self.cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        self.height = int(self.cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if resolution is not None and (self.width, self.height) != tuple(resolution):
            raise DeviceError(f"{self.name}: gives {self.width}×{self.height} px, the rig "
                              f"asks for {resolution[0]}×{resolution[1]} px")
        if exposure_ms is not None:
            self.set_exposure(exposure_ms)
        if gain is not None:
            self.set_gain(gain)

    def _set(self, prop: int, value: float, what: str) -> None:
        ok = self._reader.call(lambda: self.cap.set(prop, value), self.timeout_s,
                               f"{self.name}: set {what}")
        if not ok:
            raise DeviceError(f"{self.name} ({self.backend}): does not support setting the "
                              f"{what}")

    def set_exposure(self, exposure_ms: float) -> None:
        """Manual exposure, ms. DeviceError if the camera has no exposure control."""
        if not exposure_ms > 0:
            raise DeviceError(f"{self.name}: exposure must be > 0 ms, got {exposure_ms}")
        if self.backend == "V4L2":
            self._set(cv2.CAP_PROP_AUTO_EXPOSURE, 1, "manual exposure mode")
        self._set(cv2.CAP_PROP_EXPOSURE, _exposure_value(exposure_ms, self.backend), "exposure")
        self.exposure_ms = float(exposure_ms)

    def set_gain(self, gain: float) -> None:
        """Analog gain in the camera's units. DeviceError if it has no gain control."""
        self._set(cv2.CAP_PROP_GAIN, float(gain), "gain")

    def grab(self, timeout_s: float | None = None) -> np.ndarray:
        """One frame, (height, width) uint8 or uint16. DeviceError on timeout or when the
        camera (or the end of a file) gives no frame."""
        ok, frame = self._reader.call(self.cap.read, timeout_s or self.timeout_s,
                                      f"{self.name}: grab")
        if not ok or frame is None:
            raise DeviceError(f"{self.name}: gave no frame (unplugged, or the end of the "
                              "file or sequence)")
        if frame.ndim == 3:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY if frame.shape[2] == 4
                                 else cv2.COLOR_BGR2GRAY)
        return np.ascontiguousarray(frame)

    def close(self) -> None:
        if not self._reader.stuck:
            self._reader.call(self.cap.release, self.timeout_s, f"{self.name}: close")
        self._reader.stop()
