"""The camera's picture on the cloud: does a mark on the part show where it is?

On the simulated rig: scan the step block, mark a 10 mm QR code on its lowest step
(`services.mark.plan_mark`, `mark_on_station`), scan it again. Each scan first takes a frame
with the laser off under the room light (auto-exposed), and every point gets its grey value
(`ambient`). Rows:

- the room-light frame of each scan: exposure, frames the auto-exposure took, seconds;
- on the second cloud, points within 0.1 mm of the burns (the simulator's truth) against the
  bare top of the step (> 1 mm from any burn): their mean ambient, the contrast;
- the dark points' centroid (ambient < half the bare surface's) against the burns' centroid,
  x and y, mm: the grey values sit where the marks are.

`--picture PNG` also writes the second cloud's picture (`insitu scan --preview`'s), as
docs/step-block-cloud.png is made.

Run: .venv/bin/python benchmarks/ambient.py [--binning 2] [--seed 0] [--picture out.png]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rich.console import Console
from rich.table import Table
from scipy.spatial import cKDTree

from insitu.marking.placement import Placement
from insitu.reconstruct.preview import save_cloud_picture
from insitu.services.mark import mark_on_station
from insitu.services.plan import plan_mark
from insitu.services.room_light import station_room_light
from insitu.services.scan import scan_live
from insitu.services.station import connect
from insitu.sim.marks import _burn_samples

REGION = (-12.0, 12.0, -44.0, 44.0)
QR_AT = (0.0, -30.0)


def timed_scan(station, spacing: float):
    """(cloud, room-light row) of a live scan, the room-light frame timed on its own first."""
    t0 = time.perf_counter()
    room = station_room_light(station)
    seconds = time.perf_counter() - t0
    cloud = scan_live(station, spacing=spacing, region=REGION).cloud
    return cloud, (f"{room.exposure_ms:.1f} ms", str(room.grabs), f"{seconds:.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--binning", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spacing", type=float, default=0.25)
    ap.add_argument("--picture", default=None)
    args = ap.parse_args()
    with connect(seed=args.seed, binning=args.binning) as station:
        first, row1 = timed_scan(station, 2 * args.spacing)
        plan = plan_mark(first, Placement('qr:"SN 0042"', QR_AT, 10.0, hatch_mm=0.08),
                         station.driver)
        mark_on_station(station, plan.job)
        second, row2 = timed_scan(station, args.spacing)
        burns, _ = _burn_samples(station.world.burns)
    amb, pts = second.attributes["ambient"], second.points
    d, _ = cKDTree(burns[:, :2]).query(pts[:, :2])
    on_step = (np.abs(pts[:, 2] - np.median(pts[d < 0.1, 2])) < 0.3)
    marked, bare = on_step & (d < 0.1), on_step & (d > 1.0) & (pts[:, 1] < -21)
    dark = on_step & (amb < 0.5 * np.median(amb[bare])) & (np.abs(pts[:, 1] - QR_AT[1]) < 8)
    offset = pts[dark, :2].mean(0) - burns[:, :2].mean(0)
    table = Table(title=f"camera colours on the cloud (sim rig, binning {args.binning}, "
                        f"{len(second):,} points)")
    for c in ("measure", "value", "detail"):
        table.add_column(c, justify="right" if c == "value" else "left")
    for name, (exposure, grabs, secs) in (("scan 1", row1), ("scan 2", row2)):
        table.add_row(f"{name}: room-light exposure", exposure, f"{grabs} frames, {secs}")
    table.add_row("ambient, bare step top", f"{amb[bare].mean():.3f}", f"{bare.sum():,} points")
    table.add_row("ambient, on the marks", f"{amb[marked].mean():.3f}",
                  f"{marked.sum():,} points within 0.1 mm of a burn")
    table.add_row("contrast (1 − marked / bare)", f"{1 - amb[marked].mean() / amb[bare].mean():.2f}",
                  "the sim's mark reflects 25 % at its centre")
    table.add_row("dark points' centroid − burns' centroid, x", f"{offset[0]:+.3f} mm",
                  f"{dark.sum():,} dark points")
    table.add_row("dark points' centroid − burns' centroid, y", f"{offset[1]:+.3f} mm", "")
    Console().print(table)
    if args.picture:
        save_cloud_picture(second, args.picture, "step block, a QR code marked on its lowest step")


if __name__ == "__main__":
    main()
