"""A frame of the part under the room light, the laser off: the scan's ambient frame (each
point's grey value, the camera's picture on the cloud) and the marked part's inspection image.

The exposure is found by a short auto-exposure: the sensor is linear, so one frame at a known
exposure tells the exposure that puts the bright end of the part (the 99.95th percentile) at
70 % of full scale; a frame that saturates halves it. The camera's exposure is set back
afterwards, so the laser lines keep theirs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.devices.protocols import Camera, ExposureCamera, ScanHead
from insitu.formats.bounds import BOUNDS
from insitu.services.station import Station

TARGET = 0.70             # the bright end of the part: 70 % of full scale
BRIGHT = 99.95
"""The bright end of the part: this percentile of the frame (the insert's top is 0.4 % of a
frame: at the 99.5th it clips, its edges with it)."""
ACCEPT = (0.45, 0.90)     # ... anywhere in here is kept
SATURATED = 0.005         # more than 0.5 % of the pixels at full scale is saturated
MAX_GRABS = 4


@dataclass(frozen=True)
class RoomLightFrame:
    """image: (H, W) uint8 or uint16; exposure_ms: what it was taken with (None: the
    camera's own, unknown); grabs: frames the auto-exposure took."""

    image: np.ndarray
    exposure_ms: float | None
    grabs: int = 1


def bright_level(image: np.ndarray) -> tuple[float, float]:
    """(99.95th percentile, fraction of pixels at full scale), both 0..1 of the dtype's full
    scale, of a frame (H, W) uint8 or uint16 (every 4th pixel each way: fast, enough)."""
    full = 255 if image.dtype == np.uint8 else 65535
    sample = image[::4, ::4]
    return float(np.percentile(sample, BRIGHT)) / full, float(np.mean(sample >= full))


def next_exposure(exposure_ms: float, level: float, saturated: float) -> float | None:
    """The exposure for the next frame after one at ``exposure_ms`` gave ``level`` and
    ``saturated`` (:func:`bright_level`), within the exposure's bounds; None: keep it."""
    bound = BOUNDS["exposure_ms"]
    if saturated > SATURATED:
        new = exposure_ms / 2
    elif ACCEPT[0] <= level <= ACCEPT[1]:
        return None
    else:
        new = exposure_ms * TARGET / max(level, 1e-3)
    new = min(max(new, bound.lo), bound.hi)
    return None if np.isclose(new, exposure_ms) else new


def grab_room_light(camera: Camera, head: ScanHead, start_ms: float | None = None,
                    restore_ms: float | None = None) -> RoomLightFrame:
    """The laser off (``head.off()``), a frame under the room light, auto-exposed from
    ``start_ms`` (default: the camera's ``exposure_ms``; a camera that does not say gives
    one frame at whatever it has). The exposure is set back to ``restore_ms`` (default: the
    camera's before)."""
    head.off()
    if not isinstance(camera, ExposureCamera) or camera.exposure_ms is None:
        return RoomLightFrame(camera.grab(), None)
    before = camera.exposure_ms
    exposure, grabs = float(start_ms if start_ms is not None else before), 0
    camera.set_exposure(exposure)            # manual: a camera on its own auto is set to it
    try:
        while True:
            image = camera.grab()
            grabs += 1
            new = next_exposure(exposure, *bright_level(image))
            if new is None or grabs == MAX_GRABS:
                return RoomLightFrame(image, exposure, grabs)
            exposure = new
            camera.set_exposure(exposure)
    finally:
        back = float(restore_ms if restore_ms is not None else before)
        if exposure != back:
            camera.set_exposure(back)


def station_room_light(station: Station) -> RoomLightFrame:
    """:func:`grab_room_light` on the station's camera, starting from the exposure its last
    room-light frame needed (kept as ``station.room_light_ms``: one frame when the light has
    not changed)."""
    devices = station.devices
    room = grab_room_light(devices.camera, devices.head, start_ms=station.room_light_ms)
    station.room_light_ms = room.exposure_ms
    return room
