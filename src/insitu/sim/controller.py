"""The simulated galvo controller: it executes command lists on a
:class:`~insitu.sim.world.SimWorld` and its marks burn into the workpiece.

Mirror angles are what the driver computed with the operator's *nominal* kinematics; the head
then does what the *true* head does with them: the angles become a command on z = 0 through
the nominal forward model, and the true beam for that command (true mirror geometry plus the
true field distortion, ``rig.beams``) is ray-cast into the true scene. Where it hits, with the
laser on, the surface is burnt: a :class:`~insitu.sim.marks.Burn` polyline whose width is the
1/e² spot diameter at the hit, growing with the distance from the dynamic focus along the true
beam. The laser burns on any move while it is on (a jump with the laser on would show). A
wobble (``set_wobble``, for the rest of its list) sweeps the spot round a circle of its
amplitude as it moves: the burn is wider by twice the amplitude. Each pass of a path burns
again: a burn along the last one's samples counts as its next pass (``Burn.passes``), which
the inspection camera sees darker.

Burns are kept on the world (``SimWorld.burns``), so a resumed job on a new controller adds to the
same marks and :class:`~insitu.sim.devices.SimInspectionCamera` sees them all. On a part of an
ablation material (the blanks, :mod:`insitu.sim.ablation`) a burn removes material instead: each
sample carries the pulses fired while the spot crossed it (frequency × time at the mark speed) and
the height of the focus on its beam, and the world's surface goes down under them (an engraving is
seen by its shape, not by a darker colour).

Test instrumentation: when ``INSITU_SIM_MARK_LOG`` names a file, the controller appends what it
executes there — ``L digest n`` when a list of n commands starts, ``J i`` / ``M i x0 y0 z0 x1
y1 z1`` for each jump / move with the laser on (command index, joint from → to), ``E digest
n`` when the list ends, ``O`` at every laser-off (fsync'ed at every list end and laser-off) —
outlives the program driving it, reports the last list's position from that file after a
restart.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from insitu.devices.galvo import Command, ListPosition, focus_points, list_digest, nominal_commands
from insitu.errors import DeviceError
from insitu.geometry.beams import TwoMirrorHead
from insitu.sim.marks import Burn
from insitu.sim.scene import Scene
from insitu.sim.world import LaserState, SimWorld


class SimController:
    """Executes :class:`Command` lists on ``world``'s rig. ``burns``: the marks this
    controller made (also added to ``world.burns``); ``elapsed_s``: simulated time
    (moves at the set speeds between nominal focus points, plus delays); ``sample_mm``:
    spacing of burn samples along a move."""

    def __init__(self, world: SimWorld, sample_mm: float = 0.02, scene: Scene | None = None):
        self.world = world
        rig = world.rig
        self.nominal = TwoMirrorHead.of(rig.operator.head)
        self._scene = scene
        self.sample_mm = float(sample_mm)
        self.burns: list[Burn] = []
        self.pilot_trace: list[np.ndarray] = []
        self.laser_is_on = self.pilot_is_on = False
        self.joint = np.zeros(3)
        self.power_pct = 0.0
        self.frequency_khz = 20.0
        self.speed = {"mark": 500.0, "jump": 3000.0}
        self.wobble_mm = 0.0
        self.elapsed_s = 0.0
        self._open: list[tuple[np.ndarray, ...]] = []     # the burst's samples, not yet burnt
        self._stopped = False
        self._position: ListPosition | None = None
        self._index = 0
        log = os.environ.get(MARK_LOG_ENV)
        self._log = -1
        if log:
            self._position = last_position(log)
            self._log = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    @property
    def scene(self) -> Scene:
        """Where the marks burn: the given scene, else the world's as it is now."""
        return self._scene if self._scene is not None else self.world.renderer(False).scene

    # -- Controller --------------------------------------------------------------------------
    def execute(self, commands: Sequence[Command]) -> None:
        """Run the list; its simulated time onto the world's station clock (marking), the
        work of burning it as the simulator's CPU."""
        t0 = self.elapsed_s
        try:
            with self.world.clock.simulating():
                self._execute(commands)
        finally:
            self.world.clock.advance("marking", self.elapsed_s - t0)

    def _execute(self, commands: Sequence[Command]) -> None:
        self._stopped = False
        digest = list_digest(commands)
        self._position = ListPosition(digest, 0)
        self._note(f"L {digest} {len(commands)}")
        self.wobble_mm = 0.0                   # a wobble holds for its list only
        for i, c in enumerate(commands):
            if self._stopped:               # laser_off (from any thread) stops the list
                break
            self._index = i
            self._do(c)
            self._position = ListPosition(digest, i + 1)
        if not self._stopped:
            self._note(f"E {digest} {len(commands)}", sync=True)
        self.world.save_engravings(every_s=1.0)

    def laser_off(self) -> None:
        self._stopped = True
        self._close_burn()
        self.laser_is_on = self.pilot_is_on = False
        self.world.laser = LaserState()
        self._note("O", sync=True)
        self.world.save_engravings()

    def check(self, lists) -> None:
        """No limits beyond the driver's."""

    def position(self) -> ListPosition | None:
        """Commands of the last list executed (from the mark log after a restart)."""
        return self._position

    def _note(self, line: str, sync: bool = False) -> None:
        if self._log < 0:
            return
        if line:
            os.write(self._log, (line + "\n").encode())
        if sync:
            os.fsync(self._log)

    # -- execution ---------------------------------------------------------------------------
    def _do(self, c: Command) -> None:
        op = c.op
        if op in ("jump_abs_3d", "mark_abs_3d"):
            self._move(np.asarray(c.args, float), "jump" if op == "jump_abs_3d" else "mark")
        elif op == "laser_on":
            self.laser_is_on = True
        elif op == "laser_off":
            self._close_burn()
            self.laser_is_on = False
        elif op in ("pilot_on", "pilot_off"):
            self.pilot_is_on = op == "pilot_on"
        elif op == "set_power":
            self.power_pct = float(c.args[0])
        elif op == "set_frequency":
            self.frequency_khz = float(c.args[0])
        elif op in ("set_mark_speed", "set_jump_speed"):
            self.speed[op[4:8]] = float(c.args[0])
        elif op == "set_wobble":
            self.wobble_mm = float(c.args[0]) if c.args[1] > 0 else 0.0
        elif op.endswith("_delay"):
            self.elapsed_s += float(c.args[0]) * 1e-6
        else:
            raise DeviceError(f"sim scan head: unknown command {op!r}")

    def _move(self, target: np.ndarray, kind: str) -> None:
        a, b = focus_points(self.nominal, np.vstack([self.joint, target]))
        length = float(np.linalg.norm(b - a))
        self.elapsed_s += length / self.speed[kind]
        if self._log >= 0:
            self._note(f"M {self._index} " + " ".join(f"{v:.6f}" for v in (*self.joint, *target))
                       if self.laser_is_on else f"J {self._index}")
        if self.laser_is_on:
            # the head interpolates straight in command space (like an RTC's micro-vectors)
            n = max(int(np.ceil(length / self.sample_mm)), 1)
            t = np.linspace(0.0, 1.0, n + 1)[:, None]
            c0, c1 = nominal_commands(self.nominal, np.vstack([self.joint, target]))
            cmd = c0 + t * (c1 - c0)
            focus = self.joint[2] + t[:, 0] * (target[2] - self.joint[2])
            if self._open:
                cmd, focus = cmd[1:], focus[1:]     # the start was burnt by the previous move
            pulses = np.full(len(cmd), self.frequency_khz * 1e3 * length / n / self.speed["mark"])
            if not self._open:
                pulses[0] = 0.0                     # the path's first sample: the spot arrives
            # burnt when the laser goes off: one ray cast for the whole burst
            self._open.append((cmd, focus, np.full(len(cmd), self.wobble_mm), pulses))
        elif self.pilot_is_on:
            self.pilot_trace.append(np.vstack([a, b]))
        self.joint = target

    def burn_at(self, cmd: np.ndarray, focus_mm: np.ndarray,
                wobble_mm: np.ndarray) -> tuple[np.ndarray, ...]:
        """(N, 2) commands on z = 0, (N,) focus shifts and (N,) wobble amplitudes → where the
        true beam meets the true surface (N, 3) and the 1/e² spot diameter there, widened by
        the wobble (N,), mm (NaN where it meets nothing), the z of the focus on each beam (N,)
        mm and the scene part it met (N,) (−1: none)."""
        rig, head = self.world.rig, self.world.rig.head
        origins, dirs = rig.beams.rays(cmd)
        hits = self.scene.cast(origins, dirs)
        # true path length of the focus: the DFM's zero focuses the true field centre
        landing = rig.beams.landing(cmd)
        _, ay, _ = head.inverse(landing[:, 0], landing[:, 1], 0.0)
        e, d = head.mirror_separation_mm, head.mirror_distance_mm
        s_focus = e + d + focus_mm - e / np.cos(2 * ay)
        s_hit = np.einsum("ij,ij->i", hits.points - origins, dirs)
        width = 2.0 * rig.optics.beam_radius_mm(s_hit - s_focus)
        pts = np.where(hits.hit[:, None], hits.points, np.nan)
        focus_z = origins[:, 2] + s_focus * dirs[:, 2]
        return (pts, np.where(hits.hit, width + 2.0 * wobble_mm, np.nan), focus_z, hits.part)

    def _close_burn(self) -> None:
        if self._open:
            cmd, focus, wobble, pulses = (np.concatenate(a) for a in zip(*self._open))
            self._open = []
            pts, w, focus_z, part = self.burn_at(cmd, focus, wobble)
            burn = Burn(pts, w, self.power_pct)
            if self.world.ablate(pts, part, focus_z, pulses, self.power_pct,
                                 self.frequency_khz):
                return
            last = self.burns[-1] if self.burns else None
            if last is not None and self.world.burns and self.world.burns[-1] is last and (
                    last.again(burn)):
                burn = Burn(pts, np.fmax(w, last.widths), self.power_pct, last.passes + 1)
                self.burns[-1] = self.world.burns[-1] = burn      # a further pass: darker
            else:
                self.burns.append(burn)
                self.world.burns.append(burn)


MARK_LOG_ENV = "INSITU_SIM_MARK_LOG"


def last_position(log: str | os.PathLike) -> ListPosition | None:
    """The position of the last list in a mark log (see the module docstring), or None."""
    try:
        with open(log, "rb") as f:
            f.seek(max(f.seek(0, os.SEEK_END) - (1 << 20), 0))
            lines = f.read().decode(errors="replace").splitlines()
    except FileNotFoundError:
        return None
    done = 0
    for line in reversed(lines):
        w = line.split()
        if not w:
            continue
        try:
            if w[0] == "E":
                return ListPosition(w[1], int(w[2]))
            if w[0] in ("M", "J") and not done:
                done = int(w[1]) + 1
            if w[0] == "L":
                return ListPosition(w[1], done)
        except (IndexError, ValueError):            # a line a kill cut short
            continue
    return None
