"""Read-back on the simulated rig: do marked codes decode from the side camera's image
rectified onto the surface, and where does the camera see the mark against the plan?

For QR and Data Matrix codes at module sizes 0.2 … 0.5 mm, flat (the step block's 3 mm top,
planar) and wrapped on the arc's top (wrap), at a few rotations:

1. plan the code on a cloud of the part (its true surface sampled every 0.1 mm with 10 µm
   noise; a scan's cloud takes minutes to measure), through ``services.mark.plan_mark``;
2. mark it with the simulated head, its field correction perfect (a calibrated station) —
   and, for 0.4 mm modules at 30°, also uncorrected (the head's field distortion moves the
   mark by a few tenths of a mm: the offset the read-back must see);
3. render the true camera's frame of the marked part under room light (2448 × 2048, the
   window around the mark only, for speed), and read it back through the operator's camera
   model (calibrated, so ~0.2 mm and ~0.02° off) with ``services.inspect.read_back_image``.

Columns: decoded from the rectified picture; decoded from the raw frame (the same decoder
on the camera's window around the mark, unrectified); the offset the camera reads (u, v
along the code's axes, mm on the surface); the true offset — the sim's burns drawn in the
mark's frame and located against the plan the same way; |read − true| through the
operator's camera model and through the true camera (the method's own error, without the
camera calibration's); the grade.

Run: .venv/bin/python benchmarks/readback.py [--quick] [--seed N]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.formats.pointcloud import PointCloud
from insitu.marking import GalvoDriver, Placement, run_job
from insitu.marking.readback import decode_picture, find_offset, planned_paths
from insitu.marking.verify import render
from insitu.services.inspect import read_back_image
from insitu.services.plan import plan_mark
from insitu.services.station import simulated
from insitu.sim.controller import SimController
from insitu.sim.marks import RoomLightView, render_inspection
from insitu.sim.world import sim_world
from insitu.vision.dpm_grade import letter

console = Console(width=170)
PARTS = (("step-block", (0.0, -30.0), "planar", (-10, 10, -40, -20)),
         ("arc", (0.0, 0.0), "wrap", (-20, 20, -20, 20)))


def truth_cloud(world, region, step=0.1, seed=0) -> PointCloud:
    """The part's true surface over ``region`` every ``step`` mm, 10 µm noise."""
    x0, x1, y0, y1 = region
    g = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    z = world.parts[0].height(xy[:, 0], xy[:, 1])
    ok = np.isfinite(z)
    z = z + np.random.default_rng(seed).normal(0, 0.01, len(z))
    return PointCloud(np.column_stack([xy[ok], z[ok]]))


def window_of(camera, points: np.ndarray, pad: int = 60) -> tuple[int, int, int, int]:
    """(row0, row1, col0, col1) of the frame around ``points`` (N, 3) mm."""
    uv = camera.project(points)
    lo, hi = np.floor(uv.min(0)).astype(int) - pad, np.ceil(uv.max(0)).astype(int) + pad
    return (max(lo[1], 0), min(hi[1], camera.height), max(lo[0], 0), min(hi[0], camera.width))


def true_offset(reading, burns, projection, beam_mm: float) -> tuple[float, float] | None:
    """The burns (the sim's truth) drawn in the mark's frame, located against the plan as
    the read-back locates the camera's picture: (u, v) mm."""
    f = reading.frame
    burnt = [b.points[np.isfinite(b.points).all(1)] for b in burns]
    burnt = [b for b in burnt if len(b) > 1]
    xy = planned_paths(burnt, projection)
    truth = render(xy, f.origin, f.axes, f.size_mm, beam_mm, f.px_mm).astype(np.float32)
    planned = render(planned_paths(list(projection.paths), projection), f.origin, f.axes,
                     f.size_mm, beam_mm, f.px_mm)
    hit = find_offset(truth, planned, int(np.ceil(1.5 / f.px_mm)), 2.0 * 0.3 / f.px_mm)
    return None if hit is None else (hit[0] * f.px_mm, -hit[1] * f.px_mm)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="0.3 and 0.5 mm, one rotation")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    modules = (0.3, 0.5) if args.quick else (0.2, 0.3, 0.4, 0.5)
    rotations = (30.0,) if args.quick else (0.0, 30.0, 75.0)
    tab = Table(title="read-back of marked codes on the simulated rig (2448 × 2048 camera)")
    for col in ("part", "code", "module mm", "rot °", "rectified", "raw frame",
                "read offset u, v mm", "true offset u, v mm", "|read − true| mm",
                "… true camera", "grade",
                "seen", "s"):
        tab.add_column(col)
    stats = {"n3": 0, "ok3": 0, "raw3": 0, "n": 0, "ok": 0, "raw": 0, "err": [], "err0": []}
    for part, centre, mode, region in PARTS:
        world = sim_world(part, seed=args.seed, binning=1)
        station = simulated(world)
        cloud = truth_cloud(world, region, seed=args.seed)
        correct = GalvoDriver.from_config(world.rig.operator.head, world.rig.ideal_correction())
        cases = [(sym, m, rot, correct) for sym in ("qr", "datamatrix") for m in modules
                 for rot in rotations]
        cases += [(sym, 0.4, 30.0, station.driver) for sym in ("qr", "datamatrix")]
        view = RoomLightView(world.rig, world.renderer().scene)     # one ray cast a part
        for sym, module, rot, driver in cases:
            world.burns.clear()
            placement = Placement(f'{sym}:"SN {args.seed:04d}";module={module}',
                                  centre, None, rot, mode)
            plan = plan_mark(cloud, placement, station.driver, force=True)
            sc = SimController(world)
            run_job(plan.job, driver, sc)
            win = window_of(world.rig.camera, plan.projection.points)
            img = render_inspection(world.rig, sc.scene, sc.burns, seed=args.seed + 1,
                                    view=view)
            t = time.perf_counter()
            rb = read_back_image(img, station.rig.camera, cloud, [plan])
            dt = time.perf_counter() - t
            r = rb.readings[0]
            raw = decode_picture(img[win[0]:win[1], win[2]:win[3]].astype(np.float32),
                                 sym, module * 12)
            truth = true_offset(r, sc.burns, plan.projection, placement.beam_mm)
            r0 = read_back_image(img, world.rig.camera, cloud, [plan]).readings[0]
            err, err0 = (None if o is None or truth is None else
                         float(np.hypot(o[0] - truth[0], o[1] - truth[1]))
                         for o in (r.offset_mm, r0.offset_mm))
            ok, raw_ok = r.ok, raw == r.text
            stats["n"] += 1
            stats["ok"] += ok
            stats["raw"] += raw_ok
            if module >= 0.3:
                stats["n3"] += 1
                stats["ok3"] += ok
                stats["raw3"] += raw_ok
            if err is not None:
                stats["err"].append(err)
                stats["err0"].append(err0)
            label = sym + ("" if driver is correct else " uncorrected")
            tab.add_row(part, label, f"{module:g}", f"{rot:g}", "yes" if ok else "NO",
                        "yes" if raw_ok else "no",
                        "-" if r.offset_mm is None else "{:+.3f}, {:+.3f}".format(
                            *r.offset_mm),
                        "-" if truth is None else "{:+.3f}, {:+.3f}".format(*truth),
                        "-" if err is None else f"{err:.3f}",
                        "-" if err0 is None else f"{err0:.4f}",
                        "-" if r.grades is None else letter(r.grades.overall),
                        f"{r.seen:.0%}", f"{dt:.2f}")
    console.print(tab)
    e, e0 = np.array(stats["err"]), np.array(stats["err0"])
    console.print(f"decoded from the rectified picture: {stats['ok']} of {stats['n']} (modules "
                  f"≥ 0.3 mm: {stats['ok3']} of {stats['n3']}); from the raw frame: "
                  f"{stats['raw']} of {stats['n']} (≥ 0.3 mm: {stats['raw3']} of "
                  f"{stats['n3']}); |read − true offset| mean {e.mean():.3f} mm, max "
                  f"{e.max():.3f} mm (through the true camera: max {e0.max():.4f} mm)")


if __name__ == "__main__":
    main()
