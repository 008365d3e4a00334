"""Parts arriving on the simulated table, one per part of a production run: the same
workpiece each time, fresh (no marks), at a pose drawn for that part — reproducible from the
run's seed and the part's number, so a resumed run finds the interrupted part where it lay."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from insitu.geometry.pose import pose_matrix
from insitu.sim.workpieces import Workpiece, load_mesh_workpiece, make_workpiece, random_pose
from insitu.sim.world import SimWorld

POSE_RANGE_MM = 25.0       # a part lies within ±25 mm of where the recipe's reference lay


def part_pose(seed: int | None, part: int, range_mm: float = POSE_RANGE_MM
              ) -> tuple[float, float, float]:
    """(x mm, y mm, angle_deg) of part number ``part``: uniform within ±``range_mm`` and any
    turn about z, drawn from (``seed``, ``part``); (0, 0, 0) without a seed."""
    if seed is None:
        return 0.0, 0.0, 0.0
    return random_pose(np.random.default_rng([int(seed), int(part)]), range_mm)


def _part(workpiece: str, x: float, y: float, angle_deg: float) -> Workpiece:
    if Path(workpiece).suffix.lower() in (".stl", ".ply", ".obj"):
        return load_mesh_workpiece(workpiece, x, y, angle_deg)
    return make_workpiece(workpiece, x=x, y=y, angle_deg=angle_deg)


class SimFeeder:
    """Puts part after part of ``workpiece`` (a catalogue name or a mesh file) on ``world``'s
    table at :func:`part_pose` (``seed`` None: always where the reference lay)."""

    def __init__(self, world: SimWorld, workpiece: str, seed: int | None = None):
        self.world, self.workpiece, self.seed = world, workpiece, seed

    def present(self, part: int) -> np.ndarray:
        """Take the last part off the table, put a fresh one on at its pose; T_world_part
        (4, 4), the truth (read only by tests and benchmarks)."""
        pose = part_pose(self.seed, part)
        self.world.parts = [_part(self.workpiece, *pose)]
        self.world.burns, self.world.engravings = [], {}
        self.world.invalidate()
        return pose_matrix(*pose)
