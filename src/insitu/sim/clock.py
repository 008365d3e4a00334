"""How long the simulated station's devices take: the timing its devices advance the station
clock by (:class:`insitu.devices.clock.StationClock`, kept on the world).

Camera: a GigE Vision 5 MP global-shutter camera, as Li et al.'s (a Vieworks VH-5MG, GigE).
A frame's readout takes the longer of the sensor's (``row_us`` a row, plus ``blank_rows``:
the JAI GO-5000M-PGE's 165 clocks of 12 MHz a row, 10 blank rows) and the link's (8-bit
pixels at ``link_gbit_s``, the payload GigE carries), both for the rows and columns of the
region of interest; a frame's exposure overlaps the previous frame's readout, so a frame
takes the longer of (the head's jump and settling, the trigger's latency, the exposure) and
the readout. A region of interest moved between frames without changing its size (its
offsets written while grabbing, as many GigE Vision cameras allow, since the frames' size
stays) takes ``roi_move_ms`` (a register write's round trip over the link).

The scan's light: the head draws its lines with the marking source's beam at a power that
never marks. A line's light is energy per mm of line (power × dwell): the camera's picture
of one line at the nominal exposure (10 ms) is ``scan_dose_uj_mm`` µJ per mm of line on the
part (docs/simulator.md derives it from the rig's optics and sensor). The scan's power is
the highest whose pulses stay under ``scan_fluence_share`` of the lowest ablation threshold
of the station's materials (``scan_threshold_j_cm2``), a pulse's peak fluence being
2E / (π w²) for a pulse of E = P / f at ``scan_pulse_khz`` in the focused spot of
``scan_spot_um`` (1/e² diameter; the worst case: the part in the beam's focus) — and at most
``source_power_w``. A frame of lines is exposed for the longer of the light its lines need at
that power and one full pass over them; a laser-off or spot frame for the camera's exposure.

Head: a line is swept at the head's line speed, at most ``line_speed_mm_s`` (the galvo's)
and at most one pulse a spot diameter (a faster sweep draws a row of dots); lines drawn in
one exposure are drawn in turn, one list per frame (RTC and LMC alike), with a jump at
``jump_mm_s`` and ``settle_ms`` between them and back to the first; the list starts with a
jump from where the head was. Marking: the controller's own model (its moves at the job's
speeds, its delays); the stage: ``stage_mm_s`` and ``stage_settle_ms``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from insitu.devices.projection import SCAN_FLUENCE_SHARE
from insitu.errors import ConfigError
from insitu.formats.materials import LaserSource
from insitu.sim.render import NOMINAL_EXPOSURE_MS


@dataclass(frozen=True)
class SimTiming:
    """The simulated station's device timing (see the module docstring); seconds from
    :meth:`readout_s`, :meth:`jump_s`, :meth:`exposure_s` and :meth:`frame_s`."""

    row_us: float = 13.75
    blank_rows: int = 10
    link_gbit_s: float = 0.94
    trigger_us: float = 20.0
    jump_mm_s: float = 3000.0
    settle_ms: float = 0.3
    line_speed_mm_s: float = 10000.0
    stage_mm_s: float = 5.0
    stage_settle_ms: float = 50.0
    scan_dose_uj_mm: float = 0.27
    scan_spot_um: float = 50.0
    scan_pulse_khz: float = 1000.0
    scan_threshold_j_cm2: float = 0.7
    scan_fluence_share: float = SCAN_FLUENCE_SHARE
    source_power_w: float = 20.0
    roi_move_ms: float = 0.3

    def scan_power_w(self) -> float:
        """The highest power (W) of the scan that never marks: a pulse's peak fluence at most
        ``scan_fluence_share`` × ``scan_threshold_j_cm2``, and the source's power at most."""
        source = LaserSource(power_w=self.source_power_w, spot_um=self.scan_spot_um)
        full = source.peak_fluence_j_cm2(100.0, self.scan_pulse_khz)
        limit = self.scan_fluence_share * self.scan_threshold_j_cm2
        return self.source_power_w * min(limit / full, 1.0)

    def max_sweep_mm_s(self) -> float:
        """The fastest a line can be swept (mm/s): the galvo's, and one pulse a spot
        diameter."""
        return min(self.line_speed_mm_s, self.scan_pulse_khz * self.scan_spot_um)

    def light_s(self, length_mm: float, dose: float = 1.0) -> float:
        """Seconds of the scan's power that give ``length_mm`` of line ``dose`` times the
        nominal frame's light."""
        return dose * self.scan_dose_uj_mm * 1e-6 * length_mm / self.scan_power_w()

    def readout_s(self, rows: int, cols: int) -> float:
        """Seconds to read and send a frame of ``rows`` × ``cols`` px (8-bit)."""
        rows = rows + self.blank_rows
        return max(rows * self.row_us * 1e-6, rows * cols * 8 / (self.link_gbit_s * 1e9))

    def jump_s(self, distance_mm: float) -> float:
        """A jump of the head over ``distance_mm`` and its settling (0 when it stays)."""
        if distance_mm <= 1e-9:
            return 0.0
        return distance_mm / self.jump_mm_s + self.settle_ms * 1e-3

    def exposure_s(self, lines, exposure_ms: float, speed_mm_s: float | None) -> float:
        """The exposure (s) of a frame of ``lines`` ((start, end) mm each) swept at
        ``speed_mm_s`` that the camera set to ``exposure_ms`` takes: the light its lines
        need at the scan's power (each ``exposure_ms / K / 10 ms`` the nominal frame's: the
        camera's exposure says how much light the picture holds), delivered in whole passes
        over them — one pass at a lower power when that is enough (no jump back to the
        first line: the next frame's jump starts from the last)."""
        length = sum(float(np.linalg.norm(np.subtract(b, a))) for a, b in lines)
        light = self.light_s(length, exposure_ms / NOMINAL_EXPOSURE_MS / len(lines))
        sweep, jumps = self._sweep_s(lines, speed_mm_s), self._jumps_s(lines)
        passes = max(int(np.ceil(light / sweep - 1e-9)), 1)
        return passes * (sweep + sum(jumps)) - (jumps[-1] if jumps else 0.0)

    def _sweep_s(self, lines, speed_mm_s: float | None) -> float:
        """Sweeping every line of ``lines`` once at ``speed_mm_s`` (None: the fastest)."""
        v = speed_mm_s or self.max_sweep_mm_s()
        return sum(float(np.linalg.norm(np.subtract(b, a))) for a, b in lines) / v

    def _jumps_s(self, lines) -> list[float]:
        """The jumps from each line's end to the next's start, the last back to the first
        (none for a single line)."""
        if len(lines) < 2:
            return []
        ends = [b for _, b in lines]
        starts = [a for a, _ in lines[1:]] + [lines[0][0]]
        return [self.jump_s(float(np.linalg.norm(np.subtract(s, e))))
                for e, s in zip(ends, starts)]

    def frame_s(self, exposure_ms: float, setup_s: float, readout_s: float) -> float:
        """One frame: the head's ``setup_s`` (its jump to the list's start), the trigger's
        latency and the exposure (a laser-off frame's, or a frame of lines' own,
        :meth:`exposure_s`) — or the previous frame's ``readout_s`` when that takes longer."""
        return max(setup_s + self.trigger_us * 1e-6 + exposure_ms * 1e-3, readout_s)

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
        if key == "scan_fluence_share" and value >= 1:
            raise ConfigError(f"{at}: {value!r}: expected < 1 (at the ablation threshold the "
                              "scan marks the part)")
    return SimTiming(**{k: (int(v) if k == "blank_rows" else float(v))
                        for k, v in options.items()})
