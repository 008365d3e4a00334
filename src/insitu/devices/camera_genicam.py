"""GenICam industrial cameras (GigE Vision, USB3 Vision, …) through `harvesters` and the
camera maker's GenTL producer (a ``.cti`` file named in the rig file, loaded only if the
station file allows it: :mod:`.native`).

Features are set by their SFNC names: PixelFormat (Mono8 → uint8 frames; Mono10/12/16 and
their packed forms → uint16, unscaled: ``pixel_bits`` says how many bits are significant),
ExposureTime (µs; ExposureTimeAbs on older cameras), Gain (dB),
TriggerSelector = FrameStart with TriggerMode and TriggerSource. Trigger modes:

- ``"free"``: free-running; a grab first discards the frames already buffered, so that the
  frame returned was exposed after the call (after the scan head moved the line);
- ``"software"``: each grab fires TriggerSoftware and waits for that frame;
- ``"hardware"``: frames are exposed on an edge of ``trigger_line`` (the scan head's output
  that marks a line drawn at pilot power); a grab waits for the next one.

Buffers: the stream's StreamBufferHandlingMode is set to NewestOnly when offered; each frame
is copied out before its buffer is queued again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from harvesters.core import Harvester

from insitu.devices.native import allowed_library
from insitu.errors import ConfigError, DeviceError
from insitu.formats.bounds import check

PIXEL_FORMATS = ("Mono8", "Mono10", "Mono12", "Mono16", "Mono10p", "Mono12p", "Mono12Packed")
TRIGGERS = ("free", "software", "hardware")


class GenICamCamera:
    """A :class:`~insitu.devices.protocols.Camera`. ``producer``: the GenTL producer .cti;
    ``serial``: the camera's serial number (None: the first camera the producer finds)."""

    def __init__(self, producer: str | Path, serial: str | None = None,
                 pixel_format: str = "Mono8", trigger: str = "free",
                 trigger_line: str = "Line1", exposure_ms: float | None = None,
                 gain_db: float | None = None, num_buffers: int = 4, timeout_s: float = 5.0):
        if pixel_format not in PIXEL_FORMATS:
            raise ConfigError(f"options.camera.pixel_format: expected one of "
                              f"{', '.join(PIXEL_FORMATS)}, got {pixel_format!r}")
        if trigger not in TRIGGERS:
            raise ConfigError(f"options.camera.trigger: expected one of {', '.join(TRIGGERS)}, "
                              f"got {trigger!r}")
        for key, bound, value in (("exposure_ms", "exposure_ms", exposure_ms),
                                  ("gain_db", "gain_db", gain_db),
                                  ("num_buffers", "count", num_buffers),
                                  ("timeout_s", "timeout_s", timeout_s)):
            if value is not None:
                check(bound, value, f"options.camera.{key}", ConfigError)
        producer = Path(producer)
        if not producer.is_file():
            raise DeviceError(f"GenICam: GenTL producer {producer} not found (install the "
                              "camera maker's SDK and name its .cti file in the rig file)")
        real = allowed_library(producer, "options.camera.producer")   # the station's consent
        self.timeout_s, self.trigger = float(timeout_s), trigger
        self.harvester = Harvester()
        self.harvester.add_file(str(real), check_validity=True)
        self.harvester.update()
        found = [d.serial_number for d in self.harvester.device_info_list]
        if not found:
            self._fail_open(f"no camera found by the producer {producer.name}")
        if serial is not None and str(serial) not in found:
            self._fail_open(f"no camera with serial {serial} (found: {', '.join(found)})")
        key = {"serial_number": str(serial)} if serial is not None else 0
        try:
            self.ia = self.harvester.create(key)
        except Exception as e:                         # noqa: BLE001 — GenTL's own errors
            self._fail_open(f"cannot open the camera ({e}); is it used by another program?")
        self.name = f"GenICam camera {found[0] if serial is None else serial}"
        try:
            self._configure(pixel_format, trigger, trigger_line, exposure_ms, gain_db,
                            num_buffers)
        except BaseException:
            self.ia.destroy()
            self.harvester.reset()
            raise

    def _configure(self, pixel_format: str, trigger: str, trigger_line: str,
                   exposure_ms: float | None, gain_db: float | None, num_buffers: int) -> None:
        self.nodes = self.ia.remote_device.node_map
        self.ia.num_buffers = int(num_buffers)
        self._set_if_offered(self.ia.data_streams[0].node_map, "StreamBufferHandlingMode",
                             "NewestOnly")
        self._set("PixelFormat", pixel_format)
        self.pixel_format = pixel_format
        self.width, self.height = int(self.nodes.Width.value), int(self.nodes.Height.value)
        self._set_trigger(trigger, trigger_line)
        if exposure_ms is not None:
            self.set_exposure(exposure_ms)
        if gain_db is not None:
            self.set_gain(gain_db)
        self.ia.start()

    def _fail_open(self, why: str):
        self.harvester.reset()
        raise DeviceError(f"GenICam: {why}")

    # -- features ---------------------------------------------------------------------------
    def _node(self, name: str, nodes=None):
        nodes = nodes if nodes is not None else self.nodes
        if not nodes.has_node(name):
            raise DeviceError(f"{self.name}: has no feature {name}")
        return nodes.get_node(name)

    def _set(self, name: str, value) -> None:
        node = self._node(name)
        offered = getattr(node, "symbolics", None)
        if offered is not None and value not in offered:
            raise DeviceError(f"{self.name}: {name} {value} is not offered (the camera offers "
                              f"{', '.join(offered)})")
        try:
            node.value = value
        except Exception as e:                         # noqa: BLE001 — GenApi's own errors
            raise DeviceError(f"{self.name}: cannot set {name} to {value} ({e})") from None

    @staticmethod
    def _set_if_offered(nodes, name: str, value: str) -> None:
        if nodes.has_node(name) and value in getattr(nodes.get_node(name), "symbolics", ()):
            nodes.get_node(name).value = value

    def _set_trigger(self, trigger: str, line: str) -> None:
        if trigger == "free":
            if self.nodes.has_node("TriggerMode"):
                self._set("TriggerSelector", "FrameStart")
                self._set("TriggerMode", "Off")
            return
        self._set("TriggerSelector", "FrameStart")
        self._set("TriggerMode", "On")
        self._set("TriggerSource", "Software" if trigger == "software" else line)
        if trigger == "hardware" and self.nodes.has_node("TriggerActivation"):
            self._set("TriggerActivation", "RisingEdge")

    def set_exposure(self, exposure_ms: float) -> None:
        """Exposure time, ms (the camera takes µs)."""
        name = "ExposureTime" if self.nodes.has_node("ExposureTime") else "ExposureTimeAbs"
        self._set_if_offered(self.nodes, "ExposureAuto", "Off")
        self._set(name, float(exposure_ms) * 1000.0)
        self.exposure_ms = float(exposure_ms)

    def set_gain(self, gain_db: float) -> None:
        self._set_if_offered(self.nodes, "GainAuto", "Off")
        self._set("Gain", float(gain_db))

    # -- frames -----------------------------------------------------------------------------
    def _fetch(self, timeout_s: float):
        try:
            return self.ia.try_fetch(timeout=timeout_s)
        except Exception as e:                         # noqa: BLE001 — device lost, etc.
            raise DeviceError(f"{self.name}: acquisition failed ({e}); camera unplugged?"
                              ) from None

    def grab(self, timeout_s: float | None = None) -> np.ndarray:
        """One frame, (height, width) uint8 (Mono8) or uint16. DeviceError on timeout."""
        timeout_s = timeout_s or self.timeout_s
        if self.trigger == "free":
            while (stale := self._fetch(0.001)) is not None:     # 0 would wait for ever
                stale.queue()
        elif self.trigger == "software":
            self._node("TriggerSoftware").execute()
        buf = self._fetch(timeout_s)
        if buf is None:
            raise DeviceError(f"{self.name}: no frame within {timeout_s:g} s"
                              + (" (no trigger from the scan head?)"
                                 if self.trigger == "hardware" else ""))
        try:
            c = buf.payload.components[0]
            frame = np.array(c.data, copy=True).reshape(c.height, c.width)
        finally:
            buf.queue()
        return frame if self.pixel_format == "Mono8" else frame.astype(np.uint16, copy=False)

    @property
    def pixel_bits(self) -> int:
        """The frames' significant bits: Mono12 gives 0 … 4095 in uint16."""
        return int("".join(ch for ch in self.pixel_format[4:6] if ch.isdigit()))

    def close(self) -> None:
        try:
            self.ia.stop()
            self.ia.destroy()
        finally:
            self.harvester.reset()
