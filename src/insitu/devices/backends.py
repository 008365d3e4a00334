"""Opening the devices a rig file names (configuration chooses the backend, never probing).

Each real backend reads its block of the rig file's ``options`` (unknown keys are refused,
naming ``options.<block>.<key>``); relative paths in them are relative to the rig file:

- camera ``opencv``: ``options.camera`` = {source (device index, path or URL), resolution,
  exposure_ms, gain, timeout_s}
- camera ``genicam``: ``options.camera`` = {producer, serial, pixel_format, trigger,
  trigger_line, exposure_ms, gain_db, num_buffers, timeout_s}
- scan head ``rtc``: ``options.rtc`` = :class:`~.rtc.RtcSettings` fields
- scan head ``lmc``: ``options.lmc`` = :class:`~.lmc.LmcSettings` fields
- line projection on a real head: ``options.projection`` = {source, speed_mm_s, sweeps,
  power_pct, frequency_khz}
- stage ``grbl``: ``options.stage`` = {port, baudrate, axis, sign, offset_mm, feed_mm_min,
  z_range_mm, timeout_s, home_on_open}

A native library these name (``options.rtc.library``, ``options.camera.producer``) is loaded
only if the station file allows it (:mod:`.native`), never because the rig file names it.
"""

from __future__ import annotations

import dataclasses
import inspect
from contextlib import suppress
from dataclasses import dataclass, field
from typing import Any

from insitu.devices.galvo import Controller, FieldCorrection
from insitu.devices.protocols import Camera, ScanHead, Stage
from insitu.errors import ConfigError
from insitu.geometry.beams import TwoMirrorHead

PATH_KEYS = {"producer", "library", "correction_file", "program_dir", "materials_file"}


@dataclass
class Devices:
    """A station's opened devices. ``controller`` executes mark jobs; ``head`` projects scan lines
    (on the same scan head); ``stage`` is None without one."""

    camera: Camera
    head: ScanHead
    controller: Controller
    stage: Stage | None = None
    _closers: list = field(default_factory=list, repr=False)

    def close(self) -> None:
        """Laser off, then every device closed (never raises)."""
        with suppress(Exception):
            self.head.off()
        for close in reversed(self._closers):
            with suppress(Exception):
                close()


def _options(cfg, block: str, target) -> dict[str, Any]:
    """``options[block]`` checked against ``target``'s parameters; paths resolved."""
    if not isinstance(cfg.options.get(block, {}), dict):
        raise ConfigError(f"{cfg.path}: options.{block}: expected an object")
    opts = dict(cfg.options.get(block, {}))
    names = ({f.name for f in dataclasses.fields(target)} if dataclasses.is_dataclass(target)
             else set(inspect.signature(target).parameters))
    for key in opts:
        if key not in names:
            raise ConfigError(f"{cfg.path}: options.{block}.{key}: unknown; expected one of "
                              f"{', '.join(sorted(names))}")
        if key in PATH_KEYS and opts[key] is not None:
            opts[key] = cfg.resolve(opts[key])
    return opts


def _build(cfg, block: str, target, **fixed):
    opts = _options(cfg, block, target)
    try:
        return target(**opts, **fixed)
    except TypeError as e:
        raise ConfigError(f"{cfg.path}: options.{block}: {e}") from None
    except ConfigError as e:               # a value out of its bounds, named options.<block>.<key>
        raise ConfigError(f"{cfg.path}: {e}") from None


def open_camera(cfg, sim: Devices | None = None) -> Camera:
    if cfg.camera == "opencv":
        from insitu.devices.camera_opencv import OpenCVCamera
        opts = _options(cfg, "camera", OpenCVCamera)
        if "source" not in opts:
            raise ConfigError(f"{cfg.path}: options.camera.source: required for an OpenCV "
                              "camera (a device index such as 0, or a path)")
        if isinstance(opts["source"], str) and "://" not in opts["source"]:
            opts["source"] = str(cfg.resolve(opts["source"]))      # file, sequence, device
        try:
            return OpenCVCamera(**opts)
        except ConfigError as e:           # a value out of its bounds, named options.camera.<key>
            raise ConfigError(f"{cfg.path}: {e}") from None
    if cfg.camera == "genicam":
        from insitu.devices.camera_genicam import GenICamCamera
        if "producer" not in cfg.options.get("camera", {}):
            raise ConfigError(f"{cfg.path}: options.camera.producer: required (the GenTL "
                              "producer .cti of the camera maker)")
        return _build(cfg, "camera", GenICamCamera)
    if cfg.camera == "sim":
        return _need_sim(sim, "camera").camera
    raise ConfigError(f"{cfg.path}: camera: '{cfg.camera}' is for recorded sequences "
                      "(insitu scan replay), not a live station")


def open_controller(cfg, head: TwoMirrorHead, sim: Devices | None = None) -> Controller:
    if cfg.scan_head == "rtc":
        from insitu.devices.rtc import RtcController, RtcSettings
        return RtcController(head, _build(cfg, "rtc", RtcSettings))
    if cfg.scan_head == "lmc":
        from insitu.devices.lmc import LmcController, LmcSettings
        return LmcController(head, _build(cfg, "lmc", LmcSettings))
    return _need_sim(sim, "scan_head").controller


def open_stage(cfg, sim: Devices | None = None) -> Stage | None:
    if cfg.stage == "grbl":
        from insitu.devices.stage_grbl import GrblStage
        if "port" not in cfg.options.get("stage", {}):
            raise ConfigError(f"{cfg.path}: options.stage.port: required (e.g. /dev/ttyUSB0)")
        return _build(cfg, "stage", GrblStage)
    if cfg.stage == "sim":
        return _need_sim(sim, "stage").stage
    return None


def _need_sim(sim: Devices | None, what: str) -> Devices:
    if sim is None:
        raise ConfigError(f"{what}: 'sim' is a device of the simulated rig (the station "
                          "factory opens it)")
    return sim


def open_devices(cfg, head_config, correction: FieldCorrection | None = None,
                 sim: Devices | None = None) -> Devices:
    """The devices of ``cfg`` (a :class:`~insitu.formats.rig.RigConfig`). ``head_config``:
    the scan head's nominal geometry (a :class:`~insitu.formats.rig.ScanHeadGeometry`);
    ``correction``: the field correction for line projection; ``sim``: the simulated rig's
    devices, taken for those ``cfg`` names 'sim'. On failure, what was opened is closed
    again."""
    from insitu.devices.projection import GalvoLineProjector

    head = TwoMirrorHead.of(head_config)
    closers: list = []

    def opened(dev):
        if hasattr(dev, "close"):
            closers.append(dev.close)
        return dev

    try:
        controller = opened(open_controller(cfg, head, sim))
        if cfg.scan_head == "sim":
            projector = _need_sim(sim, "scan_head").head
        else:
            projector = _build(cfg, "projection", GalvoLineProjector, controller=controller,
                               head=head, field_size_mm=tuple(head_config.field_size_mm),
                               z_range_mm=tuple(head_config.z_range_mm), correction=correction)
        camera = opened(open_camera(cfg, sim))
        stage = opened(open_stage(cfg, sim))
    except BaseException:
        for close in reversed(closers):
            with suppress(Exception):
                close()
        raise
    return Devices(camera, projector, controller, stage, closers)
