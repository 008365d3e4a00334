"""Speed of the simulated camera: full-size (2448 × 2048) line and spot frames on one core.

Prints a table: frames rendered, mean and worst time per frame. Target: < 0.3 s a line frame.
Run: .venv/bin/python benchmarks/render_speed.py
"""

from __future__ import annotations

import os
import time

os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core, honestly

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from insitu.sim.rig import default_rig  # noqa: E402
from insitu.sim.workpieces import make_workpiece  # noqa: E402
from insitu.sim.world import SimWorld  # noqa: E402


def main(n: int = 20) -> None:
    table = Table(title="simulated camera, 2448 × 2048, one core")
    for col in ("workpiece", "frame", "frames", "first (s)", "mean (s)", "max (s)"):
        table.add_column(col)
    for name in ("step-block", "arc", "freeform"):
        world = SimWorld(default_rig(seed=0), parts=[make_workpiece(name)])
        r = world.renderer()
        for kind in ("line", "spot"):
            times = []
            for i in range(n):
                x = -10 + i * 20 / n
                t = time.perf_counter()
                if kind == "line":
                    r.line_frame([x, -45], [x, 45])
                else:
                    r.spot_frame([x, 5.0])
                times.append(time.perf_counter() - t)
            steady = np.array(times[1:])
            table.add_row(name, kind, str(n), f"{times[0]:.3f}", f"{steady.mean():.3f}",
                          f"{steady.max():.3f}")
    Console().print(table)


if __name__ == "__main__":
    main()
