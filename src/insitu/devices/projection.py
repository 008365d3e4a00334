"""Line projection for scanning on a real scan head: a :class:`~.protocols.ScanHead` over any
galvo :class:`~.galvo.Controller` (RTC, LMC).

The line is swept back and forth at pilot power — the red pilot laser (``source="pilot"``)
or the marking laser at ``power_pct`` — by a background thread that re-sends the sweep list
until the line changes, so that the camera exposes while it is drawn. Each sweep list starts
by switching the source on: that output's rising edge, wired to the camera's trigger input
(GenICam ``trigger="hardware"``), synchronises the exposure with the projection.
:meth:`show_line` returns once the new line has been drawn at least once. A controller fault
stops the thread with the laser off; the next call raises it as DeviceError.
"""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np

from insitu.devices.galvo import Command, FieldCorrection, joint_from_targets
from insitu.devices.protocols import check_in_field
from insitu.errors import ConfigError, DeviceError, SafetyError
from insitu.formats.bounds import check
from insitu.formats.materials import DEFAULT_MATERIALS, MaterialTable, read_materials
from insitu.geometry.beams import TwoMirrorHead

SCAN_FLUENCE_SHARE = 0.25
"""The most a scan's pulse may carry of the lowest ablation threshold in the station's
materials (as the simulated station scans, :mod:`insitu.sim.clock`)."""


class GalvoLineProjector:
    """``head``: nominal kinematics; ``correction``: the field correction, as for marking;
    ``speed_mm_s``: sweep speed; ``sweeps``: back-and-forth passes per list; ``materials_file``:
    the station's materials file (None: the built-in table) — the marking laser
    (``source="laser"``) is refused at a power whose pulses reach
    :data:`SCAN_FLUENCE_SHARE` of its lowest ablation threshold (the scan would mark the
    part)."""

    def __init__(self, controller, head: TwoMirrorHead, field_size_mm: tuple[float, float],
                 z_range_mm: tuple[float, float], correction: FieldCorrection | None = None,
                 speed_mm_s: float = 2000.0, sweeps: int = 4, source: str = "pilot",
                 power_pct: float = 1.0, frequency_khz: float = 20.0,
                 first_draw_timeout_s: float = 5.0,
                 materials_file: str | Path | None = None):
        if source not in ("pilot", "laser"):
            raise DeviceError(f"line projection: source must be 'pilot' or 'laser', got {source!r}")
        for key, bound, value in (("speed_mm_s", "mark_speed_mm_s", speed_mm_s),
                                  ("sweeps", "sweeps", sweeps),
                                  ("power_pct", "power_pct", power_pct),
                                  ("frequency_khz", "frequency_khz", frequency_khz)):
            check(bound, value, f"options.projection.{key}", ConfigError)
        if source == "laser":
            table = DEFAULT_MATERIALS if materials_file is None else read_materials(
                materials_file)
            _never_marks(table, float(power_pct), float(frequency_khz))
        self.controller, self.head, self.correction = controller, head, correction
        self.field_size_mm, self.z_range_mm = tuple(field_size_mm), tuple(z_range_mm)
        self.speed, self.sweeps, self.source = float(speed_mm_s), int(sweeps), source
        self.power_pct, self.frequency_khz = float(power_pct), float(frequency_khz)
        self.first_draw_timeout_s = first_draw_timeout_s
        self._lock = threading.Condition()
        self._list: list[Command] | None = None
        self._generation = self._drawn = 0
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None

    # -- lists --------------------------------------------------------------------------------
    def joint(self, xy, focus_z: float) -> tuple[float, float, float]:
        """Command (x, y) on z = 0, mm → joint with the focus at height ``focus_z`` on its beam."""
        j = joint_from_targets(self.head, np.array([[xy[0], xy[1], 0.0]]), self.correction)[0]
        tx, ty = 2 * np.radians(j[0]), 2 * np.radians(j[1])
        x, y = self.head.forward(tx, ty, focus_z)
        df = float(self.head.focus_shift(np.atleast_1d(x), np.atleast_1d(y),
                                         np.atleast_1d(float(focus_z)))[0])
        return float(j[0]), float(j[1]), df

    def sweep_list(self, start, end, focus_z: float = 0.0) -> list[Command]:
        a, b = self.joint(start, focus_z), self.joint(end, focus_z)
        on, off = (("pilot_on", "pilot_off") if self.source == "pilot" else
                   ("laser_on", "laser_off"))
        cmds = [Command("set_mark_speed", (self.speed,)), Command("jump_abs_3d", a)]
        if self.source == "laser":
            cmds += [Command("set_power", (self.power_pct,)),
                     Command("set_frequency", (self.frequency_khz,))]
        cmds.append(Command(on))
        for _ in range(self.sweeps):
            cmds += [Command("mark_abs_3d", b), Command("mark_abs_3d", a)]
        return cmds + [Command(off)]

    def _check(self, *points) -> None:
        check_in_field(self.field_size_mm, *points)

    def set_line_speed(self, speed_mm_s: float) -> None:
        """Sweep speed of the lines drawn from now on, mm/s."""
        if not speed_mm_s > 0:
            raise SafetyError(f"scan head: line speed {speed_mm_s:g} mm/s: expected > 0")
        self.speed = float(speed_mm_s)

    def show_line(self, start, end, focus_z: float = 0.0) -> None:
        self._check(start, end)
        self._show(self.sweep_list(start, end, focus_z))

    def show_lines(self, lines, focus_z: float = 0.0) -> None:
        """Several lines in one list, each swept as :meth:`show_line` sweeps one (the
        source off on the jumps between them): they share the camera's exposure."""
        lines = list(lines)
        if len(lines) == 1:
            return self.show_line(*lines[0], focus_z)
        self._check(*(p for line in lines for p in line))
        cmds = [c for a, b in lines for c in self.sweep_list(a, b, focus_z)]
        self._show(cmds)

    def show_spot(self, xy, focus_z: float = 0.0) -> None:
        self._check(xy)
        j = self.joint(xy, focus_z)
        on, off = ("pilot_on", "pilot_off") if self.source == "pilot" else ("laser_on", "laser_off")
        self._show([Command("jump_abs_3d", j), Command(on), Command("mark_delay", (20000.0,)),
                    Command(off)])

    def _show(self, cmds: list[Command]) -> None:
        with self._lock:
            self._raise_error()
            self._list = cmds
            self._generation += 1
            want = self._generation
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name="line projection",
                                                daemon=True)
                self._thread.start()
            ok = self._lock.wait_for(lambda: self._drawn >= want or self._error is not None,
                                     self.first_draw_timeout_s)
            self._raise_error()
        if not ok:
            self.off()
            raise DeviceError(f"line projection: the scan head did not draw the line "
                              f"within {self.first_draw_timeout_s:g} s")

    def _raise_error(self) -> None:
        if self._error is not None:
            raise DeviceError(f"line projection stopped: {self._error}") from self._error

    def _run(self) -> None:
        while True:
            with self._lock:
                cmds, gen = self._list, self._generation
            if cmds is None:
                return
            try:
                self.controller.execute(cmds)
            except BaseException as e:                 # noqa: BLE001 — handed to the caller
                self.controller.laser_off()
                with self._lock:
                    self._error, self._list, self._thread = e, None, None
                    self._lock.notify_all()
                return
            with self._lock:
                self._drawn = max(self._drawn, gen)
                self._lock.notify_all()

    def off(self) -> None:
        """Stop projecting; laser and pilot off at once. Never raises."""
        with self._lock:
            self._list, self._error = None, None
            thread, self._thread = self._thread, None
        try:
            self.controller.laser_off()
        finally:
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout=5.0)
            self.controller.laser_off()        # after the last sweep list ended


def _never_marks(materials: MaterialTable, power_pct: float, frequency_khz: float) -> None:
    """SafetyError when the marking laser at ``power_pct`` % and ``frequency_khz`` would mark
    the softest of ``materials`` (pulses beyond :data:`SCAN_FLUENCE_SHARE` of its threshold)."""
    soft, laser = materials.softest(), materials.laser
    fluence = laser.peak_fluence_j_cm2(power_pct, frequency_khz)
    limit = SCAN_FLUENCE_SHARE * soft.threshold_j_cm2
    if fluence > limit:
        most = power_pct * limit / fluence
        raise SafetyError(
            f"options.projection: the marking laser at {power_pct:g} % and {frequency_khz:g} kHz "
            f"puts {fluence:.3g} J/cm² in each pulse, over {SCAN_FLUENCE_SHARE:g} × the "
            f"ablation threshold of {soft.name} ({soft.threshold_j_cm2:g} J/cm²): the scan "
            f"would mark the part; set power_pct ≤ {most:.3g} at this frequency, or source "
            f"'pilot'")
