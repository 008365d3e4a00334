"""Speed of reconstruction: a 200-frame 2448 × 2048 scan on one core, after the frames are read
(target < 4 s), for Method 1 and Method 2 (ours), with the extraction split out.

Frames: 20 distinct simulated frames of the step block, each used 10 times. Memory stays flat:
the reconstructor keeps only points.
Run: .venv/bin/python benchmarks/scan_speed.py
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core, honestly

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from insitu.reconstruct.scan import ScanReconstructor  # noqa: E402
from insitu.services import calibrate_height, centre_settings, height_model  # noqa: E402
from insitu.services.record import record_height_calibration  # noqa: E402
from insitu.services.station import simulated
from insitu.sim.devices import SimCamera, SimScanHead  # noqa: E402
from insitu.sim.rig import default_rig  # noqa: E402
from insitu.sim.workpieces import make_workpiece  # noqa: E402
from insitu.sim.world import SimWorld  # noqa: E402
from insitu.vision.extract import CentreSettings, extract_centres  # noqa: E402


def main(n_frames: int = 200) -> None:
    rig = default_rig(seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        record_height_calibration(simulated(SimWorld(rig)), Path(tmp) / "h", heights=(-15.0, 0.0, 15.0),
                                  offsets=(-20.0, -10.0, 0.0, 10.0, 20.0))
        cal = calibrate_height(Path(tmp) / "h")
    world = SimWorld(rig, parts=[make_workpiece("step-block")], seed=1)
    cam, head = SimCamera(world), SimScanHead(world)
    lines, frames = [], []
    for x in np.linspace(-9.5, 9.5, 20):
        a, b = np.array([x, -46.0]), np.array([x, 46.0])
        head.show_line(a, b)
        lines.append((a, b))
        frames.append(cam.grab())
    H, zr = rig.operator.head.pivot_height_mm, rig.operator.head.z_range_mm
    cal_cam, model = height_model(cal)
    table = Table(title=f"{n_frames} frames of 2448 × 2048, one core (target < 4 s)")
    for col in ("stage", "total (s)", "per frame (ms)", "frames/s"):
        table.add_column(col)

    def timed(name, fn):
        t = time.perf_counter()
        for i in range(n_frames):
            fn(i)
        dt = time.perf_counter() - t
        table.add_row(name, f"{dt:.2f}", f"{1000 * dt / n_frames:.1f}", f"{n_frames / dt:.0f}")

    timed("gray centroid only (paper, k = 0.5)",
          lambda i: extract_centres(frames[i % 20], CentreSettings(k=0.5, smooth_half_window=0)))
    timed("our centres (k = 0.3, smoothing)", lambda i: extract_centres(frames[i % 20]))
    for name, rec in (("Method 1 (plane), whole scan",
                       ScanReconstructor(rig.operator.camera, H, z_range_mm=zr)),
                      ("Method 2 (ours), whole scan",
                       ScanReconstructor(cal_cam, H, height_model=model,
                                         settings=centre_settings(cal), z_range_mm=zr))):
        def step(i, rec=rec):
            rec.add(i, frames[i % 20], *lines[i % 20])
        timed(name, step)
        t1 = time.perf_counter()
        cloud = rec.cloud()
        table.add_row("  + cloud, outlier removal", f"{time.perf_counter() - t1:.2f}",
                      f"{len(cloud):,} points", "")
    Console().print(table)


if __name__ == "__main__":
    main()
