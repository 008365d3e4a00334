"""The simulated station's world: the true rig, the parts on the table, the calibration plate
or board, the laser's state, the marks burnt so far and the material they removed. The
simulated devices (:mod:`insitu.sim.devices`) share one world, as ophyd's simulated detectors
respond to simulated motors.

The material removed from a part (:mod:`insitu.sim.ablation`) changes its surface for every
camera frame after it; it outlives the program when ``INSITU_SIM_ENGRAVING`` names a file (as
the part would stay on a real table): the world reads it when made and writes it when the
controller's laser goes off, and at most once a second in between.
"""

from __future__ import annotations

import io
import json
import os
import time
from dataclasses import dataclass, field

import numpy as np

from insitu.devices.clock import StationClock
from insitu.formats.atomic import atomic_write_bytes
from insitu.sim.ablation import ABLATION, Engraving, MarkingBeam, ablate, engraved_part
from insitu.sim.clock import SimTiming
from insitu.sim.render import Renderer
from insitu.sim.rig import SimRig, default_rig
from insitu.sim.scene import Scene
from insitu.sim.workpieces import (
    Pose,
    Workpiece,
    load_mesh_workpiece,
    make_workpiece,
    part_matrix,
    to_part,
    workpiece_at,
)

ENGRAVING_ENV = "INSITU_SIM_ENGRAVING"


@dataclass
class LaserState:
    """What the head shows: nothing ("off"), a ``"line"`` start → end, several lines in one
    exposure (``"lines"``: ``lines``, (start, end) each; ``start``, ``end`` the first's) or
    a ``"spot"`` at ``start``; mm on z = 0, focused at ``focus_z``. Its timing: the head's
    jump to it (``setup_s``, counted by the next frame) and the speed its lines are swept at
    (``speed_mm_s``; None: the head's fastest)."""

    kind: str = "off"                       # "off" | "line" | "lines" | "spot"
    start: np.ndarray | None = None
    end: np.ndarray | None = None
    focus_z: float = 0.0
    lines: tuple = ()
    setup_s: float = 0.0
    speed_mm_s: float | None = None


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
    of the catalogue's (:class:`insitu.sim.scene.Scene`); ``engravings``: the material removed
    from ``parts[i]`` (:class:`~insitu.sim.ablation.Engraving`, only parts of an ablation
    material); ``beam``: the true marking laser; ``plate``: the side (mm) of the pocket
    plate's pockets cut in ``parts[0]`` (:func:`~insitu.sim.pocket_plate.cut_plate`; None:
    none)."""

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
    engravings: dict[int, Engraving] = field(default_factory=dict)
    beam: MarkingBeam = field(default_factory=MarkingBeam)
    plate: float | None = None
    _renderer: Renderer | None = field(default=None, repr=False)
    _built: dict = field(default_factory=dict, repr=False)  # i → (engraving, version, part)
    _rng: np.random.Generator | None = field(default=None, repr=False)
    _saved: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng([self.seed, 331])
        self._load_engravings()

    def scene_parts(self) -> list[Workpiece]:
        """The table, or the calibration plate on the Z stage in its place, and the parts with
        the material removed from them."""
        parts = [self._engraved(i) for i in range(len(self.parts))]
        if self.plate_z is not None:
            return [make_workpiece("plate", top_z=self.plate_z)] + parts
        return [make_workpiece("table")] + parts

    def _engraved(self, i: int) -> Workpiece:
        eng = self.engravings.get(i)
        if eng is None:
            return self.parts[i]
        built = self._built.get(i)
        if built is None or built[0] is not eng or built[1] != eng.version:
            built = self._built[i] = (eng, eng.version, engraved_part(self.parts[i], eng))
        return built[2]

    def renderer(self, fresh: bool = True) -> Renderer:
        """The camera's renderer; ``fresh``: its scene with the material removed so far (a
        marking controller takes the scene as it is: a burn's position hardly moves as the
        floor goes down, and the removal itself is computed on the engraving's grid)."""
        if self._renderer is None:
            self._renderer = Renderer(self.rig, self._scene(), seed=self.seed)
        elif fresh and any(i not in self._built or self._built[i][0] is not e
                           or self._built[i][1] != e.version
                           for i, e in self.engravings.items()):
            self.invalidate()
        return self._renderer

    def ablate(self, points: np.ndarray, scene_part: np.ndarray, focus_z: np.ndarray,
               pulses: np.ndarray, power_pct: float, frequency_khz: float) -> bool:
        """Remove material where a burn's samples met a part of an ablation material:
        ``points`` (N, 3) world mm, ``scene_part`` (N,) their index in the scene's parts (0:
        the table), ``focus_z`` (N,) z of the focus on each sample's beam, ``pulses`` (N,)
        fired there. Returns whether any part was engraved."""
        done = False
        for k in np.unique(scene_part[scene_part > 0]):
            i = int(k) - 1
            part = self.parts[i]
            material = ABLATION.get(part.name)
            if material is None:
                continue
            sel = scene_part == k
            u, v = to_part(part, points[sel, 0], points[sel, 1])
            uv = np.column_stack([u, v])
            eng = self.engravings.setdefault(i, Engraving(material, seed=self.seed + 7919 * i))
            eng.cover(part, uv.min(0), uv.max(0))
            done |= ablate(eng, self.beam, uv, focus_z[sel], pulses[sel], power_pct,
                           frequency_khz, self._rng)
        return done

    def true_depth(self, x: np.ndarray, y: np.ndarray, index: int = 0) -> np.ndarray:
        """Depth (mm) removed from ``parts[index]`` at world (x, y): the truth that scores a
        measured pocket (0 where nothing was removed)."""
        eng = self.engravings.get(index)
        if eng is None:
            return np.zeros(np.shape(x))
        return eng.depth_at(*to_part(self.parts[index], x, y))

    # -- the engraved parts outlive the program (INSITU_SIM_ENGRAVING) -----------------------
    def _key(self, i: int) -> str:
        return json.dumps([self.parts[i].name, self.parts[i].params], sort_keys=True)

    def _load_engravings(self) -> None:
        path = os.environ.get(ENGRAVING_ENV)
        if not path or not os.path.exists(path):
            return
        with np.load(path, allow_pickle=False) as z:
            for i in range(len(self.parts)):
                key = f"p{i}"
                if f"{key}_removed" in z and str(z[f"{key}_key"]) == self._key(i):
                    material = ABLATION[self.parts[i].name]
                    eng = Engraving(material, seed=self.seed + 7919 * i)
                    eng.restore(self.parts[i], z[f"{key}_origin"], z[f"{key}_removed"])
                    eng.version = int(z[f"{key}_version"])
                    self.engravings[i] = eng

    def save_engravings(self, every_s: float = 0.0) -> None:
        """Write the engravings to ``INSITU_SIM_ENGRAVING`` (when set), at most every
        ``every_s`` seconds."""
        path = os.environ.get(ENGRAVING_ENV)
        if not path or not self.engravings or time.monotonic() - self._saved < every_s:
            return
        arrays = {}
        for i, eng in self.engravings.items():
            arrays |= {f"p{i}_removed": eng.removed, f"p{i}_key": np.array(self._key(i)),
                       f"p{i}_origin": eng.origin, f"p{i}_version": np.array(eng.version)}
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        atomic_write_bytes(path, buf.getvalue())
        self._saved = time.monotonic()

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
        → world), the pockets of a plate (:func:`~insitu.sim.pocket_plate.pocket_truth`) when
        it has them, with ``extra`` (a recording's ``truth.json``)."""
        from insitu.sim.pocket_plate import pocket_truth

        pockets = {"pockets": pocket_truth(self)} if self.plate is not None else {}
        return {"rig": self.rig.truth_dict(),
                "workpieces": [{"name": p.name, "params": p.params,
                                "T_world_part": part_matrix(p).tolist()} for p in self.parts],
                **pockets, **extra}

    def place_part(self, pose: Pose, index: int = 0) -> None:
        """Put part ``index`` down again at ``pose`` (x, y mm, turn about z, degrees)."""
        part, (x, y, angle) = self.parts[index], pose
        if "path" in part.params:
            self.parts[index] = load_mesh_workpiece(part.params["path"], x, y, angle)
        else:
            self.parts[index] = make_workpiece(part.name, **{**part.params, "x": x, "y": y,
                                                             "angle_deg": angle})
        self._built.pop(index, None)             # its engraving moves with it
        self.invalidate()

    def clear_table(self) -> None:
        """Take the parts off the table (for a calibration on the plate)."""
        self.parts = []
        self.engravings, self._built, self.plate = {}, {}, None
        self.invalidate()


def sim_world(workpiece: str = "step-block", seed: int = 0, binning: int = 1,
              rig: SimRig | None = None, pose: Pose = (0.0, 0.0, 0.0)) -> SimWorld:
    """The simulated station with ``workpiece`` (a catalogue name, a plate of
    :data:`~insitu.sim.pocket_plate.PLATES` or a mesh file) on the table at ``pose`` (x, y mm,
    turn about z, degrees)."""
    from insitu.sim.pocket_plate import PLATES, cut_plate

    world = SimWorld(rig or default_rig(seed=seed, binning=binning),
                     parts=[workpiece_at(PLATES.get(workpiece, workpiece), pose)], seed=seed)
    if workpiece in PLATES:
        cut_plate(world)
    return world
