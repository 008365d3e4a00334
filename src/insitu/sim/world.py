"""The simulated station's world: the true rig, the parts on the table, the calibration plate
or board, the laser's state and the marks burnt so far. The simulated devices
(:mod:`insitu.sim.devices`) share one world, as ophyd's simulated detectors respond to
simulated motors."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from insitu.devices.clock import StationClock
from insitu.sim.clock import SimTiming
from insitu.sim.render import Renderer
from insitu.sim.rig import SimRig, default_rig
from insitu.sim.scene import Scene
from insitu.sim.workpieces import (Pose, Workpiece, load_mesh_workpiece, make_workpiece,
                                   part_matrix, workpiece_at)


@dataclass
class LaserState:
    """What the head shows: nothing ("off"), a ``"line"`` start → end, several lines in one
    exposure (``"lines"``: ``lines``, (start, end) each; ``start``, ``end`` the first's) or
    a ``"spot"`` at ``start``; mm on z = 0, focused at ``focus_z``. Its timing: the head's
    jump to it (``setup_s``, counted by the next frame) and one cycle over its lines
    (``cycle_s``)."""

    kind: str = "off"                       # "off" | "line" | "lines" | "spot"
    start: np.ndarray | None = None
    end: np.ndarray | None = None
    focus_z: float = 0.0
    lines: tuple = ()
    setup_s: float = 0.0
    cycle_s: float = 0.0


@dataclass
class SimWorld:
    """The virtual station. ``parts``: what stands on the table; ``plate_z``: height of the
    calibration plate's top on the Z stage (which then stands in for the table), None when no
    plate is mounted; ``burns``: the marks burnt into the parts so far
    (:class:`insitu.sim.marks.Burn`, world frame), shared by every controller and camera;
    ``board``: a calibration board in view (anything with ``frame(laser) -> image``, see
    :mod:`insitu.sim.board`), None when there is none. ``clock``: the station's time, which
    the devices advance by ``timing`` (:mod:`insitu.sim.clock`); ``head_xy``: where the
    head's last list left it (mm on z = 0); ``materials``: parts' materials by name in place
    of the catalogue's (:class:`insitu.sim.scene.Scene`)."""

    rig: SimRig
    parts: list[Workpiece] = field(default_factory=list)
    plate_z: float | None = None
    seed: int = 0
    laser: LaserState = field(default_factory=LaserState)
    burns: list = field(default_factory=list)
    board: object | None = None
    clock: StationClock = field(default_factory=StationClock)
    timing: SimTiming = field(default_factory=SimTiming)
    head_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    materials: dict | None = None
    _renderer: Renderer | None = field(default=None, repr=False)

    def scene_parts(self) -> list[Workpiece]:
        """The table, or the calibration plate on the Z stage in its place."""
        if self.plate_z is not None:
            return [make_workpiece("plate", top_z=self.plate_z)] + list(self.parts)
        return [make_workpiece("table")] + list(self.parts)

    def renderer(self) -> Renderer:
        if self._renderer is None:
            self._renderer = Renderer(self.rig, self._scene(), seed=self.seed)
        return self._renderer

    def invalidate(self) -> None:
        """The scene changed (stage moved, part placed): rebuild it on the next frame, keeping
        the sensor's speckle and noise generator."""
        if self._renderer is not None:
            self._renderer.set_scene(self._scene())

    def _scene(self) -> Scene:
        return Scene(self.scene_parts(), seed=self.seed, materials=self.materials)

    def footprint(self, margin: float = 3.0) -> tuple[float, float, float, float]:
        """The parts' footprint plus a margin (2 × along y), (x0, x1, y0, y1) mm."""
        if not self.parts:
            return (-20.0, 20.0, -45.0, 45.0)
        lo = np.min([p.bounds()[0] for p in self.parts], axis=0)
        hi = np.max([p.bounds()[1] for p in self.parts], axis=0)
        return (lo[0] - margin, hi[0] + margin, lo[1] - 2 * margin, hi[1] + 2 * margin)

    def truth(self, **extra) -> dict:
        """The true rig and parts, each with its pose ``T_world_part`` (4 × 4: its own frame
        → world), with ``extra`` (a recording's ``truth.json``)."""
        return {"rig": self.rig.truth_dict(),
                "workpieces": [{"name": p.name, "params": p.params,
                                "T_world_part": part_matrix(p).tolist()} for p in self.parts],
                **extra}

    def place_part(self, pose: Pose, index: int = 0) -> None:
        """Put part ``index`` down again at ``pose`` (x, y mm, turn about z, degrees)."""
        part, (x, y, angle) = self.parts[index], pose
        if "path" in part.params:
            self.parts[index] = load_mesh_workpiece(part.params["path"], x, y, angle)
        else:
            self.parts[index] = make_workpiece(part.name, **{**part.params, "x": x, "y": y,
                                                             "angle_deg": angle})
        self.invalidate()

    def clear_table(self) -> None:
        """Take the parts off the table (for a calibration on the plate)."""
        self.parts = []
        self.invalidate()


def sim_world(workpiece: str = "step-block", seed: int = 0, binning: int = 1,
              rig: SimRig | None = None, pose: Pose = (0.0, 0.0, 0.0)) -> SimWorld:
    """The simulated station with ``workpiece`` (a catalogue name or a mesh file) on the
    table at ``pose`` (x, y mm, turn about z, degrees)."""
    return SimWorld(rig or default_rig(seed=seed, binning=binning),
                    parts=[workpiece_at(workpiece, pose)], seed=seed)
