"""Station seconds of the step block's 0.5 mm scan, one line a frame against several lines per
exposure, whole frame against the region of interest (issue 32): the simulated station's
timing (:class:`insitu.sim.clock.SimTiming`, the rig file's ``options.sim_timing``), as its
devices advance the station clock for each frame the scan takes — the head's jump to its
list, the exposure (the light its lines need at the scan's power, at least one pass over
them), the readout of the frame or of the region of interest — the frames not drawn. Then
the bounds: the light alone at the scan's power, the sweeps alone at the head's speed, and
what 1/8 of one line a frame would need.

The scan's power is the highest that never marks (a pulse's peak fluence a quarter of the
lowest ablation threshold of the station's materials); packed: the survey frame and one
laser-off frame per packed exposure counted; the room-light frame before the lines is left
out of every row. Data: insitu's simulator (rig seed 11, binning 1: 2448 × 2048), the
step block's footprint; the survey's heights as it measured them (-0.6 … 15.6 mm).

Run: .venv/bin/python benchmarks/multiline_clock.py [--speed 10000]
"""

from __future__ import annotations

import argparse

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.reconstruct.bands import Packing
from insitu.reconstruct.packing import FramePlan
from insitu.services.scan import plan_lines, reconstructor
from insitu.services.scan_frames import drawing_order, region_of_interest
from insitu.services.station import simulated
from insitu.sim.clock import SimTiming, roi_size
from insitu.sim.render import NOMINAL_EXPOSURE_MS
from insitu.sim.world import sim_world

SURVEYED = (-0.6, 15.6)     # the step block's heights as its survey frame measures them


def scan_seconds(timing: SimTiming, frames, rows: int, cols: int, speed: float,
                 laser_off: tuple[int, ...] = ()) -> float:
    """Station seconds of ``frames`` (lists of (start, end) mm lines), each given the light
    of one nominal frame a line, read out at ``rows`` × ``cols``, swept at ``speed``;
    ``laser_off``: the line counts of the laser-off frames taken at their exposures."""
    at, total = np.zeros(2), 0.0
    readout = timing.readout_s(rows, cols)
    for f in frames:
        drawn = drawing_order(f, at) if len(f) > 1 else f
        setup = timing.jump_s(float(np.linalg.norm(np.asarray(drawn[0][0]) - at)))
        at = np.asarray(drawn[-1][1] if len(drawn) > 1 else drawn[0][0], float)
        exposure = timing.exposure_s(drawn, NOMINAL_EXPOSURE_MS * len(f), speed)
        total += timing.frame_s(exposure * 1e3, setup, readout)
    return total + sum(timing.frame_s(NOMINAL_EXPOSURE_MS * k, 0.0, readout) for k in laser_off)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", type=float, default=None,
                    help="line speed, mm/s (default: the head's fastest)")
    args = ap.parse_args()
    world = sim_world("step-block", seed=11, binning=1)
    station = simulated(world)
    rig, timing = station.rig, world.timing
    speed = args.speed or timing.max_sweep_mm_s()
    lines = plan_lines(station.default_region(), 0.5)
    rec = reconstructor(rig.camera, rig.head.pivot_height_mm, False, rig.head.z_range_mm,
                        None, None, "timing")
    roi = region_of_interest(rec, lines)
    plans = {}
    for most in (2, 3, 4):          # at most this many lines a frame, as their bands allow
        plan = FramePlan(lines, rec.sheets, rig.head.z_range_mm, "auto", Packing(most_lines=most))
        packed = plan.surveys() + plan.frames((SURVEYED[0] + 0.5, SURVEYED[1] - 0.5))
        plans[f"≤ {most} (auto)"] = (
            [list(f.lines) for f in packed],
            tuple(sorted({len(f.lines) for f in packed if len(f.lines) > 1 and not f.survey})))
    length = sum(float(np.linalg.norm(np.subtract(b, a))) for a, b in lines)
    power = timing.scan_power_w()
    t = Table(title=f"station seconds, step block, {len(lines)} lines 0.5 mm apart "
                    f"({length:.0f} mm), binning 1, swept at {speed:g} mm/s; the scan's power "
                    f"{power:.2f} W ({timing.scan_pulse_khz:g} kHz, "
                    f"{timing.scan_fluence_share:g} × F_th {timing.scan_threshold_j_cm2:g} "
                    f"J/cm²), {timing.scan_dose_uj_mm:g} µJ a mm of line")
    for col in ("frames", "camera reads", "lines a frame", "station s", "× one line a frame"):
        t.add_column(col)
    base = None
    ways = [("1", [[line] for line in lines], ())] + [(k, *v) for k, v in plans.items()]
    for window, (what, frames, off) in [(w, way) for w in (None, roi) for way in ways]:
        rows, cols = roi_size(window, rig.camera.width, rig.camera.height)
        total = scan_seconds(timing, frames, rows, cols, speed, off)
        base = base or total
        t.add_row(str(len(frames) + len(off)),
                  "whole frame" if window is None else f"{cols} × {rows} px", what,
                  f"{total:.3f}", f"{total / base:.3f}")
    light, sweep = timing.light_s(length), length / speed
    t.add_row("-", "-", f"the light alone: {length:.0f} mm at {power:.2f} W", f"{light:.4f}",
              f"{light / base:.4f}")
    t.add_row("-", "-", f"the sweeps alone: {length:.0f} mm at {speed:g} mm/s", f"{sweep:.3f}",
              f"{sweep / base:.3f}")
    t.add_row("-", "-", f"1/8: the sweeps alone at {length / (base / 8) / 1e3:.1f} m/s",
              f"{base / 8:.3f}", "0.125")
    Console(width=160).print(t)


if __name__ == "__main__":
    main()
