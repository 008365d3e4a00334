"""How long the simulated station's devices take: the timing its devices advance the station
clock by (:class:`insitu.devices.clock.StationClock`, kept on the world).

Camera: a GigE Vision 5 MP global-shutter camera, as Li et al.'s (a Vieworks VH-5MG, GigE).
A frame's readout takes the longer of the sensor's (``row_us`` a row, plus ``blank_rows``:
the JAI GO-5000M-PGE's 165 clocks of 12 MHz a row, 10 blank rows) and the link's (8-bit
pixels at ``link_gbit_s``, the payload GigE carries), both for the rows and columns of the
region of interest; a frame's exposure overlaps the previous frame's readout, so a frame
takes the longer of (the head's jump and settling, the trigger's latency, the exposure) and
the readout. The exposure lasts at least one full cycle of the lines it sees.

Head: a line is swept at the head's line speed; lines drawn in one exposure are drawn in
turn, one list per frame (RTC and LMC alike), with a jump at ``jump_mm_s`` and ``settle_ms``
between them and back to the first; the list starts with a jump from where the head was.
Each line gets the light of ``exposure / K`` of a frame of K lines (the jumps' dark time is
left out of the light, not of the time). Marking: the controller's own model (its moves at
the job's speeds, its delays); the stage: ``stage_mm_s`` and ``stage_settle_ms``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from insitu.errors import ConfigError


@dataclass(frozen=True)
class SimTiming:
    """The simulated station's device timing (see the module docstring); seconds from
    :meth:`readout_s`, :meth:`jump_s`, :meth:`cycle_s` and :meth:`frame_s`."""

    row_us: float = 13.75
    blank_rows: int = 10
    link_gbit_s: float = 0.94
    trigger_us: float = 20.0
    jump_mm_s: float = 3000.0
    settle_ms: float = 0.3
    line_speed_mm_s: float = 10000.0
    stage_mm_s: float = 5.0
    stage_settle_ms: float = 50.0

    def readout_s(self, rows: int, cols: int) -> float:
        """Seconds to read and send a frame of ``rows`` × ``cols`` px (8-bit)."""
        rows = rows + self.blank_rows
        return max(rows * self.row_us * 1e-6, rows * cols * 8 / (self.link_gbit_s * 1e9))

    def jump_s(self, distance_mm: float) -> float:
        """A jump of the head over ``distance_mm`` and its settling (0 when it stays)."""
        if distance_mm <= 1e-9:
            return 0.0
        return distance_mm / self.jump_mm_s + self.settle_ms * 1e-3

    def cycle_s(self, lines, speed_mm_s: float | None) -> float:
        """One pass over every line of ``lines`` ((start, end) mm each), swept at
        ``speed_mm_s`` (None: :attr:`line_speed_mm_s`), with the jumps between them and
        back to the first (a single line is swept back and forth: no jump)."""
        v = speed_mm_s or self.line_speed_mm_s
        sweep = sum(float(np.linalg.norm(np.subtract(b, a))) for a, b in lines) / v
        if len(lines) < 2:
            return sweep
        ends = [b for _, b in lines]
        starts = [a for a, _ in lines[1:]] + [lines[0][0]]
        return sweep + sum(self.jump_s(float(np.linalg.norm(np.subtract(s, e))))
                           for e, s in zip(ends, starts))

    def frame_s(self, exposure_ms: float, setup_s: float, readout_s: float,
                cycle_s: float = 0.0) -> float:
        """One frame: the head's ``setup_s`` (its jump to the list's start), the trigger's
        latency and the exposure (at least ``cycle_s``, one pass over its lines) — or the
        previous frame's ``readout_s`` when that takes longer."""
        exposure = max(exposure_ms * 1e-3, cycle_s)
        return max(setup_s + self.trigger_us * 1e-6 + exposure, readout_s)

    def stage_s(self, distance_mm: float) -> float:
        """A move of the Z stage over ``distance_mm`` and its settling."""
        if distance_mm <= 1e-9:
            return 0.0
        return distance_mm / self.stage_mm_s + self.stage_settle_ms * 1e-3


def roi_size(roi: tuple[int, int, int, int] | None, width: int, height: int
             ) -> tuple[int, int]:
    """(rows, cols) read out for a region of interest (u0, v0, u1, v1) px, ends excluded
    (None: the whole frame of ``width`` × ``height``)."""
    if roi is None:
        return height, width
    u0, v0, u1, v1 = roi
    return v1 - v0, u1 - u0


def timing_from(options, where: str) -> SimTiming:
    """The rig file's ``options.sim_timing`` block (``where``: the file, for messages):
    :class:`SimTiming` with the fields it names (the rest the default's); ConfigError naming
    ``options.sim_timing.<key>`` for an unknown key or a value that is not a number > 0
    (``blank_rows``: a whole number ≥ 0)."""
    if not isinstance(options, dict):
        raise ConfigError(f"{where}: options.sim_timing: expected an object")
    names = {f.name for f in fields(SimTiming)}
    for key, value in options.items():
        at = f"{where}: options.sim_timing.{key}"
        if key not in names:
            raise ConfigError(f"{at}: unknown; expected one of {', '.join(sorted(names))}")
        whole = key == "blank_rows"
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not np.isfinite(value) or (value < 0 if whole else value <= 0)
                or (whole and value != int(value))):
            raise ConfigError(f"{at}: {value!r}: expected "
                              + ("a whole number ≥ 0" if whole else "a number > 0"))
    return SimTiming(**{k: (int(v) if k == "blank_rows" else float(v))
                        for k, v in options.items()})
