"""The operator's rig model: what the station knows of its camera and scan head, and which
calibrations it measures and marks with — the same on a real rig and on the simulated one
(whose truth stays inside :mod:`insitu.sim`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from insitu.errors import ConfigError
from insitu.formats.calibration import CameraCalibration
from insitu.formats.json_file import load_json_model
from insitu.formats.rig import RigConfig, ScanHeadConfig, ScanHeadGeometry
from insitu.geometry.camera import CameraModel

SIMULATED = ("sim",)
"""Backends of the simulated rig (``replay`` and ``none`` open no device)."""


@dataclass(frozen=True)
class RigModel:
    """``camera``: as calibrated (intrinsics, pose in the scan-head frame); ``head``: the
    scan head's nominal geometry; ``field_correction``, ``height_calibration``: the files to
    mark and measure with (None: none)."""

    camera: CameraModel
    head: ScanHeadGeometry
    field_correction: Path | None = None
    height_calibration: Path | None = None

    def describe(self, kind: str) -> tuple[str, str]:
        """(camera, scan head) one-liners for a status line; ``kind`` says which rig."""
        cam, head = self.camera, self.head
        return (f"camera {cam.width}×{cam.height} px ({kind})",
                f"head {head.lens}, field {head.field_size_mm[0]:g}×{head.field_size_mm[1]:g} "
                f"mm, z {head.z_range_mm[0]:g}…{head.z_range_mm[1]:g} mm")


def simulated_devices(cfg: RigConfig) -> list[str]:
    """The devices of ``cfg`` that the simulator drives."""
    return [name for name, backend in (("camera", cfg.camera), ("scan_head", cfg.scan_head),
                                       ("stage", cfg.stage)) if backend in SIMULATED]


def rig_model(cfg: RigConfig, default: RigModel | None = None) -> RigModel:
    """The rig model a rig file describes: the camera and scan head of the files it names,
    else ``default``'s (the simulated operator's), and its calibration files. A real camera
    or head needs its file (ConfigError naming the field); so does a rig without
    ``default``."""
    for device, backend, calib, name in (
            ("camera", cfg.camera, cfg.camera_calibration, "camera_calibration"),
            ("scan_head", cfg.scan_head, cfg.scan_head_config, "scan_head_config")):
        if (backend not in SIMULATED + ("replay",) or default is None) and not calib:
            raise ConfigError(f"{cfg.path}: {name}: required with a real {device} "
                              f"('{backend}'): the measurement needs its calibration")
    camera = default.camera if default is not None else None
    if cfg.camera_calibration:
        spec = load_json_model(cfg.resolve(cfg.camera_calibration), CameraCalibration).camera
        camera = CameraModel.from_dict(spec.model_dump())
    head = default.head if default is not None else None
    if cfg.scan_head_config:
        head = load_json_model(cfg.resolve(cfg.scan_head_config), ScanHeadConfig).geometry()
    return RigModel(camera, head, cfg.resolve(cfg.field_correction),
                    cfg.resolve(cfg.height_calibration))
