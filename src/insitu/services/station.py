"""The station: the operator's rig model and the devices a rig file names — real ones, or the
simulated rig's (the only place that picks the simulator) — and the scan-head driver with its
field correction; what scanning, recording and marking need, for the commands and the
application alike."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from insitu.devices.backends import Devices, open_devices
from insitu.devices.clock import StationClock
from insitu.errors import ConfigError, SafetyError
from insitu.formats.json_file import load_json_model
from insitu.formats.project import SIM_BINNING
from insitu.formats.rig import RigConfig
from insitu.formats.rig_record import RigRecord, describe, same_rig
from insitu.marking import GalvoDriver
from insitu.rig.model import RigModel, rig_model, simulated_devices

if TYPE_CHECKING:
    from insitu.sim.world import SimWorld


class Station:
    """``rig``: the operator's rig model; ``world``: the simulated world when the rig is
    (partly) simulated, else None; ``driver``: nominal kinematics with the field correction
    of the file ``field``; ``devices``: camera, line projector, job controller, stage —
    opened on first use, so planning never touches the hardware. Close it when done (laser
    off, devices released); it is a context manager. ``record``: which rig and workpiece
    this is, as clouds and jobs record it (None: unknown). ``room_light_ms``: the exposure
    the last frame under the room light needed (:mod:`insitu.services.room_light`);
    ``mark_pace``: the board's own pace, wall seconds per planned second of its last jobs
    (:func:`insitu.services.mark.board_seconds`; None: nothing marked yet)."""

    def __init__(self, rig: RigModel, cfg: RigConfig, world: SimWorld | None = None,
                 field: Path | None = None, rig_file: Path | None = None,
                 record: RigRecord | None = None):
        self.rig, self.cfg, self.world, self.rig_file = rig, cfg, world, rig_file
        self.record = record
        self.room_light_ms: float | None = None
        self.mark_pace: float | None = None
        self._devices: Devices | None = None
        self.use_field(field)

    def use_field(self, field: Path | None) -> None:
        """Apply the field correction file ``field`` (None: none) to every job from now on."""
        from insitu.calibrate.field_file import load_field_correction

        correction = load_field_correction(field).correct if field is not None else None
        self.driver: GalvoDriver = GalvoDriver.from_config(self.rig.head, correction)
        self.field = field
        self.close()                 # the devices reopen with it (the projector corrects too)

    @property
    def devices(self) -> Devices:
        if self._devices is None:
            from insitu.sim.devices import sim_devices

            sim = sim_devices(self.world) if self.world is not None else None
            self._devices = open_devices(self.cfg, self.rig.head, self.driver.correction, sim)
        return self._devices

    def close(self) -> None:
        if self._devices is not None:
            self._devices.close()
            self._devices = None

    def __enter__(self) -> "Station":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def clock(self) -> StationClock | None:
        """The station's own time, which its devices advance (:mod:`insitu.devices.clock`):
        the simulated rig's; None on a real rig (its time is the wall clock's)."""
        return self.world.clock if self.world is not None else None

    def describe(self) -> tuple[str, str]:
        """(camera, scan head) one-liners for a status line."""
        return self.rig.describe("sim" if self.rig_file is None else f"rig {self.rig_file.name}")

    def truth(self, **extra) -> dict | None:
        """On the simulated rig, the true rig and parts (a recording's ``truth.json``) with
        ``extra``; None on a real one."""
        return None if self.world is None else self.world.truth(**extra)

    def check_source(self, source: Path, record: RigRecord | None, what: str) -> str | None:
        """Refuse (SafetyError) the ``what`` ("cloud", "job") at ``source`` when its ``record``
        names another rig or workpiece than this station's; a warning line when it has none."""
        if record is None:
            return (f"{source} does not record the rig it was {_MADE[what]} (an older file or "
                    f"another source): not checked against this station ({describe(self.record)})"
                    if self.record else None)
        if self.record is not None and not same_rig(record, self.record):
            raise SafetyError(f"{source}: the {what} was {_MADE[what]} {describe(record)}, "
                              f"the station is {describe(self.record)}; nothing marked")
        return None

    def part_feeder(self, workpiece: str, seed: int | None):
        """On the simulated rig, ``present(part) -> T_world_part``: a fresh ``workpiece`` put
        on the table for each part, at a random pose drawn from (``seed``, part) (None: where
        the reference lay); None on a real rig (the operator puts the parts on)."""
        if self.world is None:
            return None
        from insitu.geometry.pose import flat_pose
        from insitu.sim.feeder import SimFeeder

        feeder = SimFeeder(self.world, workpiece, seed)

        def present(part: int):
            T = feeder.present(part)          # clouds and jobs record where the part lies
            rest = {k: v for k, v in (self.record or {}).items() if k != "pose"}
            self.record = {**rest, **pose_record(flat_pose(T))}
            return T
        return present

    def default_region(self) -> tuple[float, float, float, float]:
        """Where to scan when no region is given: the simulated parts' footprint; a real rig
        does not know where its part is (ConfigError)."""
        if self.world is None:
            raise ConfigError("region: a scan on a real rig needs one (X0 X1 Y0 Y1, mm): insitu "
                              "does not know where the part lies", field="region")
        return self.world.footprint()


_MADE = {"cloud": "measured on", "job": "planned for"}


def simulated(world: SimWorld, field: Path | None = None,
              record: RigRecord | None = None) -> Station:
    """The station of the simulated ``world``, its operator knowing what its rig model says."""
    return Station(world.rig.operator, RigConfig(), world, field, record=record)


def pose_record(pose: tuple[float, float, float]) -> RigRecord:
    """The record's ``pose`` entry of a simulated part at ``pose`` (none at the origin)."""
    return {"pose": [float(v) for v in pose]} if any(pose) else {}


def connect(rig_file: Path | None = None, workpiece: str = "step-block", seed: int = 0,
            binning: int = SIM_BINNING, field: Path | None = None,
            pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Station:
    """The station a rig file names (devices chosen by it, never probed), or the simulated
    rig with ``workpiece`` on the table at ``pose`` (x, y mm, turn about z, degrees). A rig
    file with simulated devices simulates ``workpiece`` with its ``sim_seed``, the operator
    knowing what its calibration files say. ``field``: the field correction file to apply
    (default: the rig file's, if it names one)."""
    from insitu.sim.world import sim_world  # the simulator (Open3D) only when simulated

    if rig_file is None:
        return simulated(sim_world(workpiece, seed=seed, binning=binning, pose=pose), field,
                         {"workpiece": workpiece, "seed": seed, "binning": binning,
                          **pose_record(pose)})
    cfg = load_json_model(rig_file, RigConfig)
    world = None
    if simulated_devices(cfg):
        world = sim_world(workpiece, seed=cfg.sim_seed, binning=binning, pose=pose)
        if "sim_timing" in cfg.options:
            from insitu.sim.clock import timing_from

            world.timing = timing_from(cfg.options["sim_timing"], str(rig_file))
    rig = rig_model(cfg, world.rig.operator if world is not None else None)
    if world is not None and cfg.camera in ("sim", "replay"):
        size, sim = (rig.camera.width, rig.camera.height), world.rig.camera
        if size != (sim.width, sim.height):
            raise ConfigError(f"{cfg.camera_calibration}: camera is {size[0]}×{size[1]} px, "
                              f"the rig's is {sim.width}×{sim.height} px")
    if world is not None:            # the simulated head reads angles as the driver wrote them
        world.rig = replace(world.rig, operator=rig)
    record: RigRecord = {"rig_file": Path(rig_file).name}
    if world is not None:
        record |= {"workpiece": workpiece, "seed": cfg.sim_seed, **pose_record(pose)}
    return Station(rig, cfg, world, field if field is not None else rig.field_correction,
                   Path(rig_file), record)
