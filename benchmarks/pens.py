"""Pens: what each built-in pen does to one job — a hatched text on the simulated rig's table.

For each pen: the job's estimated time (insitu job show's: passes, jump speed and delays),
the simulated head's clock for the same commands (moves at the set speeds plus the delays it
waits), the burns the simulated laser left (one per path, its passes counted in it), their
mean width (wobble: wider by twice its amplitude) and how much light a burn's centre line
loses (1 − 0.25^passes), and the list sizes the boards get (RTC calls; LMC list entries,
where a wobble is traced in the list).

Run: .venv/bin/python benchmarks/pens.py [--text AB] [--width 10] [--hatch 0.1]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.devices.lmc import LmcListBuilder, LmcSettings
from insitu.devices.rtc import RtcListBuilder, RtcSettings
from insitu.formats.pens import DEFAULT_PENS
from insitu.marking import GalvoDriver, Placement, estimate_time, make_job, run_job, with_pen
from insitu.sim.controller import SimController
from insitu.sim.marks import mark_darkness
from insitu.sim.rig import default_rig
from insitu.sim.world import SimWorld


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--text", default="AB")
    ap.add_argument("--width", type=float, default=10.0)
    ap.add_argument("--hatch", type=float, default=0.1)
    args = ap.parse_args()
    rig = default_rig(seed=0, binning=4)
    placement = Placement(f'text:"{args.text}"', (0.0, 0.0), args.width, hatch_mm=args.hatch)
    paths = [np.column_stack([p, np.zeros(len(p))])
             for p in placement.polylines(placement.placed())]
    driver = GalvoDriver.from_config(rig.operator.head)
    rtc = RtcSettings(library=Path("unused.so"), correction_file=Path("unused.ct5"),
                      k_bits_per_mm=2000.0)
    table = Table(title=f'text:"{args.text}", {args.width:g} mm, hatch {args.hatch:g} mm: '
                        f"{len(paths)} paths on the simulated table")
    for col in ("pen", "estimated s", "simulated s", "burns", "passes", "width mm", "darkness",
                "RTC calls", "LMC entries", "run s"):
        table.add_column(col, justify="left" if col == "pen" else "right")
    for pen in DEFAULT_PENS.pens:
        job = with_pen(make_job(paths), pen)
        sim = SimController(SimWorld(rig, parts=[]))
        t0 = time.perf_counter()
        run_job(job, driver, sim)
        run_s = time.perf_counter() - t0
        lists = driver.compile(job)
        rb, lb = RtcListBuilder(driver.head, rtc), LmcListBuilder(driver.head, LmcSettings(1500.0))
        rtc_calls = sum(len(rb.calls(c)[0]) for c in lists)
        lmc_entries = sum(len(lb.commands(c)[0]) for c in lists)
        widths = np.concatenate([b.widths for b in sim.burns])
        centres = np.array([b.points[len(b.points) // 2] for b in sim.burns])
        dark = mark_darkness(centres[np.isfinite(centres).all(1)], sim.burns)
        table.add_row(pen.name, f"{estimate_time(job).total_s:.3f}",
                      f"{sim.elapsed_s:.3f}", str(len(sim.burns)),
                      str(max(b.passes for b in sim.burns)), f"{np.nanmean(widths):.3f}",
                      f"{dark.mean():.3f}", f"{rtc_calls:,}", f"{lmc_entries:,}",
                      f"{run_s:.1f}")
    console = Console(width=max(Console().width, 110))
    console.print(table)
    for pen in DEFAULT_PENS.pens:
        console.print(f"{pen.name}: {pen.summary()}", highlight=False)


if __name__ == "__main__":
    main()
