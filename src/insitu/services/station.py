"""Connecting the station: the rig file's devices (or the simulated rig), the operator's
calibration of them, and the scan-head driver with its field correction — what scanning and
marking on a live rig need, for the commands and the application alike."""

from __future__ import annotations

from pathlib import Path

from insitu.devices.backends import Station as Devices
from insitu.devices.backends import open_station
from insitu.devices.sim import SimWorld
from insitu.marking import GalvoDriver
from insitu.rig.files import RigConfig, load_json_model
from insitu.services.scan import sim_world, sim_world_from_rig_file


class Station:
    """``world``: the operator's knowledge of the rig (and, on the simulated rig, the
    simulation itself); ``driver``: nominal kinematics with the field correction of the file
    ``field``; ``devices``: camera, line projector, job controller, stage — opened on first
    use, so planning never touches the hardware. Close it when done (laser off, devices
    released); it is a context manager."""

    def __init__(self, cfg: RigConfig, world: SimWorld, field: Path | None,
                 rig_file: Path | None = None):
        self.cfg, self.world, self.rig_file = cfg, world, rig_file
        self._devices: Devices | None = None
        self.use_field(field)

    def use_field(self, field: Path | None) -> None:
        """Apply the field correction file ``field`` (None: none) to every job from now on."""
        from insitu.calibrate.field_file import load_field_correction

        correction = load_field_correction(field).correct if field is not None else None
        self.driver: GalvoDriver = GalvoDriver.from_config(self.world.rig.nominal, correction)
        self.field = field
        self.close()                 # the devices reopen with it (the projector corrects too)

    @property
    def devices(self) -> Devices:
        if self._devices is None:
            self._devices = open_station(self.cfg, self.world.rig.nominal, self.world,
                                         self.driver.correction)
        return self._devices

    def close(self) -> None:
        if self._devices is not None:
            self._devices.close()
            self._devices = None

    def __enter__(self) -> "Station":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def describe(self) -> tuple[str, str]:
        """(camera, scan head) one-liners for a status line."""
        cam, head = self.world.rig.operator_camera, self.world.rig.nominal
        kind = "sim" if self.rig_file is None else f"rig {self.rig_file.name}"
        return (f"camera {cam.width}×{cam.height} px ({kind})",
                f"head {head.lens}, field {head.field_size_mm[0]:g}×{head.field_size_mm[1]:g} "
                f"mm, z {head.z_range_mm[0]:g}…{head.z_range_mm[1]:g} mm")


def connect(rig_file: Path | None = None, workpiece: str = "step-block", seed: int = 0,
            binning: int = 1, field: Path | None = None) -> Station:
    """The station a rig file names (devices chosen by it, never probed), or the simulated
    rig with ``workpiece`` on the table. ``field``: the field correction file to apply
    (default: the rig file's, if it names one)."""
    if rig_file is None:
        return Station(RigConfig(), sim_world(workpiece, seed=seed, binning=binning), field)
    cfg = load_json_model(rig_file, RigConfig)
    world = sim_world_from_rig_file(rig_file, workpiece, binning, allow_real=True)
    return Station(cfg, world, field if field is not None else cfg.resolve(cfg.field_correction),
                   Path(rig_file))
