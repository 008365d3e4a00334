"""Low-level galvo commands and the controller that executes them (after MeerK40t's balormk:
a driver turns jobs into command lists, a controller sends them to the head).

Units at this boundary: mirror angles in degrees (mechanical, α = θ/2 of Mikkelstrup et al.),
dynamic-focus shift in mm (relative to focus on the field centre at z = 0), speeds mm/s at
the work surface, power %, frequency kHz, delays µs.

Commands (``Command.op``, ``args``):
  jump_abs_3d / mark_abs_3d (alpha_x_deg, alpha_y_deg, focus_mm) — move fast with the laser off
  / at mark speed with whatever is on; laser_on, laser_off, pilot_on, pilot_off;
  set_power (pct), set_frequency (kHz), set_mark_speed, set_jump_speed (mm/s);
  set_wobble (amplitude_mm, frequency_hz): a circle traced around the moving spot while
  marking, until the end of its list (a list without it marks without wobble);
  laser_on_delay, laser_off_delay, jump_delay, mark_delay, polygon_delay (µs): waits.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from insitu.errors import SafetyError
from insitu.geometry.beams import TwoMirrorHead

MOVES = ("jump_abs_3d", "mark_abs_3d")
SETTINGS = ("set_power", "set_frequency", "set_mark_speed", "set_jump_speed")
DELAYS = ("laser_on_delay", "laser_off_delay", "jump_delay", "mark_delay", "polygon_delay")
SWITCHES = ("laser_on", "laser_off", "pilot_on", "pilot_off")
WOBBLE = "set_wobble"

FieldCorrection = Callable[[np.ndarray], np.ndarray]
"""(N, 2) nominal commands on z = 0, mm → (N, 2) corrected commands, mm."""


@dataclass(frozen=True, slots=True)
class Command:
    op: str
    args: tuple[float, ...] = ()

    def text(self) -> str:
        """One line of a golden listing (fixed precision)."""
        if self.op in MOVES:
            ax, ay, f = self.args
            return f"{self.op} ax={ax:+.6f} ay={ay:+.6f} df={f:+.5f}"
        if self.op in SETTINGS:
            return f"{self.op} {self.args[0]:.3f}"
        if self.op in DELAYS:
            return f"{self.op} {self.args[0]:.1f}"
        if self.op == WOBBLE:
            return f"{self.op} a={self.args[0]:.4f} f={self.args[1]:.1f}"
        return self.op


@runtime_checkable
class Controller(Protocol):
    """Executes command lists on a scan head (sim, recording, or a real RTC / JCZ board)."""

    def execute(self, commands: Sequence[Command]) -> None:
        """Run the commands in order and return when done. Raises DeviceError on a fault."""
        ...

    def laser_off(self) -> None:
        """Marking laser and pilot off, at once. Never raises."""
        ...

    def check(self, lists: Sequence[Sequence[Command]]) -> None:
        """Convert every list as :meth:`execute` would, sending nothing: SafetyError for the
        first command outside the device's limits (bit range, focus, speeds, power)."""
        ...

    def position(self) -> ListPosition | None:
        """How far the board got in the last list it ran, as it last reported (None: it
        reports nothing)."""
        ...


@dataclass(frozen=True)
class ListPosition:
    """``digest``: :func:`list_digest` of the list; ``done``: its first ``done`` commands were
    executed by the board."""

    digest: str
    done: int


def check_setting(device: str, command: Command) -> None:
    """SafetyError for a speed or frequency that is not a finite number > 0, a power outside
    0 … 100 %, a delay that is not a finite number ≥ 0, a wobble not ≥ 0 or a non-finite move
    (``device`` names the board in the message)."""
    op, args = command.op, command.args
    if op in MOVES and not all(math.isfinite(a) for a in args):
        raise SafetyError(f"{device}: {op} {args}: not a finite position")
    if op in DELAYS and not (math.isfinite(args[0]) and args[0] >= 0):
        raise SafetyError(f"{device}: {op.replace('_', ' ')} {args[0]:g} µs: expected a finite "
                          "number ≥ 0")
    if op == WOBBLE and not all(math.isfinite(a) and a >= 0 for a in args):
        raise SafetyError(f"{device}: wobble {args[0]:g} mm at {args[1]:g} Hz: expected finite "
                          "numbers ≥ 0")
    if op == "set_power" and not 0.0 <= args[0] <= 100.0:
        raise SafetyError(f"{device}: power {args[0]:g} %: expected 0 … 100 %")
    if op in ("set_frequency", "set_mark_speed", "set_jump_speed") and not (
            math.isfinite(args[0]) and args[0] > 0):
        unit = "kHz" if op == "set_frequency" else "mm/s"
        raise SafetyError(f"{device}: {op[4:].replace('_', ' ')} {args[0]:g} {unit}: expected "
                          "a finite number > 0")


def list_digest(commands: Sequence[Command]) -> str:
    """SHA-256 of a command list's golden listing (identifies a list across processes)."""
    return hashlib.sha256("".join(c.text() + "\n" for c in commands).encode()).hexdigest()


def position_of(controller: Controller, commands: Sequence[Command]) -> int | None:
    """Commands of ``commands`` the controller reports done when its last list was this one
    (None: it reports no position, or its last list was another)."""
    pos = controller.position()
    if pos is None or pos.digest != list_digest(commands):
        return None
    return min(max(pos.done, 0), len(commands))


class RecordingController:
    """Records every command (for golden listings and tests); tracks the laser state."""

    def __init__(self) -> None:
        self.commands: list[Command] = []
        self.laser_is_on = False
        self.pilot_is_on = False
        self.off_calls = 0

    def execute(self, commands: Sequence[Command]) -> None:
        for c in commands:
            self.commands.append(c)
            if c.op in ("laser_on", "laser_off"):
                self.laser_is_on = c.op == "laser_on"
            elif c.op in ("pilot_on", "pilot_off"):
                self.pilot_is_on = c.op == "pilot_on"

    def laser_off(self) -> None:
        self.laser_is_on = self.pilot_is_on = False
        self.off_calls += 1

    def check(self, lists: Sequence[Sequence[Command]]) -> None:
        """No device limits."""

    def position(self) -> ListPosition | None:
        return None

    def listing(self) -> str:
        """The recorded commands, one per line."""
        return "".join(c.text() + "\n" for c in self.commands)


# ----------------------------------------------------------------------- kinematics
def joint_from_targets(head: TwoMirrorHead, points: np.ndarray,
                       correction: FieldCorrection | None = None) -> np.ndarray:
    """(N, 3) targets, world mm → (N, 3) [alpha_x_deg, alpha_y_deg, focus_mm] (Eqs. 3–5).

    With a field correction: the target's nominal beam crosses z = 0 at Q' (Mikkelstrup
    et al. §2.3); the correction turns Q' into the command K; the mirrors go to K's angles and
    the focus to the path length where K's beam reaches the target's height."""
    p = np.asarray(points, float).reshape(-1, 3)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    ax, ay, _ = head.inverse(x, y, z)
    if correction is not None:
        qx, qy = head.forward(2 * ax, 2 * ay, 0.0)
        k = np.asarray(correction(np.column_stack([qx, qy])), float).reshape(-1, 2)
        ax, ay, _ = head.inverse(k[:, 0], k[:, 1], 0.0)
        x, y = head.forward(2 * ax, 2 * ay, z)
    df = head.focus_shift(x, y, z)
    return np.column_stack([np.degrees(ax), np.degrees(ay), df])


def focus_points(head: TwoMirrorHead, joint: np.ndarray) -> np.ndarray:
    """(N, 3) [alpha_x_deg, alpha_y_deg, focus_mm] → (N, 3) where ``head``'s beam is focused,
    mm: along the beam at path length e + d + focus from the first mirror."""
    j = np.asarray(joint, float).reshape(-1, 3)
    tx, ty = 2 * np.radians(j[:, 0]), 2 * np.radians(j[:, 1])
    o, d = head.rays_from_angles(tx, ty)
    e = head.mirror_separation_mm
    s = e + head.mirror_distance_mm + j[:, 2] - e / np.cos(ty)
    return o + s[:, None] * d


def nominal_commands(head: TwoMirrorHead, joint: np.ndarray) -> np.ndarray:
    """(N, 3) joint → (N, 2) where ``head``'s beam crosses z = 0 (the command), mm."""
    j = np.asarray(joint, float).reshape(-1, 3)
    x, y = head.forward(2 * np.radians(j[:, 0]), 2 * np.radians(j[:, 1]), 0.0)
    return np.column_stack([x, y])
