"""Sim backends: a camera that sees what the sim scan head draws on the sim workpiece.

The three devices share one :class:`SimWorld` (the true rig, the parts on the table and the
current state of the laser and the stage), as ophyd's simulated detectors respond to simulated
motors.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from insitu.devices.protocols import check_in_field
from insitu.errors import SafetyError
from insitu.sim.render import NOMINAL_EXPOSURE_MS, Renderer
from insitu.sim.rig import SimRig
from insitu.sim.scene import Scene
from insitu.sim.workpieces import Workpiece, make_workpiece


@dataclass
class LaserState:
    kind: str = "off"                       # "off" | "line" | "spot"
    start: np.ndarray | None = None
    end: np.ndarray | None = None
    focus_z: float = 0.0


@dataclass
class SimWorld:
    """The virtual station. ``parts``: what stands on the table; ``plate_z``: height of the
    calibration plate's top on the Z stage (which then stands in for the table), None when no
    plate is mounted; ``burns``: the marks burnt into the parts so far
    (:class:`insitu.sim.marks.Burn`, world frame), shared by every controller and camera."""

    rig: SimRig
    parts: list[Workpiece] = field(default_factory=list)
    plate_z: float | None = None
    seed: int = 0
    laser: LaserState = field(default_factory=LaserState)
    burns: list = field(default_factory=list)
    _renderer: Renderer | None = field(default=None, repr=False)

    def scene_parts(self) -> list[Workpiece]:
        """The table, or the calibration plate on the Z stage in its place."""
        if self.plate_z is not None:
            return [make_workpiece("plate", top_z=self.plate_z)] + list(self.parts)
        return [make_workpiece("table")] + list(self.parts)

    def renderer(self) -> Renderer:
        if self._renderer is None:
            self._renderer = Renderer(self.rig, Scene(self.scene_parts(), seed=self.seed),
                                      seed=self.seed)
        return self._renderer

    def invalidate(self) -> None:
        """The scene changed (stage moved, part placed): rebuild it on the next frame, keeping
        the sensor's speckle and noise generator."""
        if self._renderer is not None:
            self._renderer.set_scene(Scene(self.scene_parts(), seed=self.seed))


class SimCamera:
    def __init__(self, world: SimWorld):
        self.world = world
        self.width, self.height = world.rig.camera.width, world.rig.camera.height
        self.exposure_ms = NOMINAL_EXPOSURE_MS

    def set_exposure(self, exposure_ms: float) -> None:
        self.exposure_ms = float(exposure_ms)

    def grab(self, timeout_s: float = 5.0) -> np.ndarray:
        r, laser = self.world.renderer(), self.world.laser
        if laser.kind == "line":
            return r.line_frame(laser.start, laser.end, self.exposure_ms, laser.focus_z)
        if laser.kind == "spot":
            return r.spot_frame(laser.start, self.exposure_ms, laser.focus_z)
        return r.ambient_frame(self.exposure_ms)


class SimScanHead:
    def __init__(self, world: SimWorld):
        self.world = world
        nominal = world.rig.nominal
        self.field_size_mm = tuple(nominal.field_size_mm)
        self.z_range_mm = tuple(nominal.z_range_mm)

    def _check(self, *points) -> None:
        check_in_field(self.field_size_mm, *points)

    def set_line_speed(self, speed_mm_s: float) -> None:
        """Accepted and checked; the simulated head draws the whole line within every
        exposure, whatever its speed."""
        if not speed_mm_s > 0:
            raise SafetyError(f"scan head: line speed {speed_mm_s:g} mm/s: expected > 0")
        self.speed_mm_s = float(speed_mm_s)

    def show_line(self, start, end, focus_z: float = 0.0) -> None:
        self._check(start, end)
        self.world.laser = LaserState("line", np.asarray(start, float), np.asarray(end, float),
                                      float(focus_z))

    def show_spot(self, xy, focus_z: float = 0.0) -> None:
        self._check(xy)
        self.world.laser = LaserState("spot", np.asarray(xy, float), None, float(focus_z))

    def off(self) -> None:
        self.world.laser = LaserState()


class SimStage:
    """Z stage carrying the calibration plate."""

    def __init__(self, world: SimWorld):
        self.world = world

    def move_z(self, z_mm: float) -> None:
        self.world.plate_z = float(z_mm)
        self.world.invalidate()

    def position_z(self) -> float:
        return float(self.world.plate_z if self.world.plate_z is not None else np.nan)
