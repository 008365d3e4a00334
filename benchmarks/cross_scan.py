"""The crossed pass on the simulated rig (realistic calibration errors): how well each pass
measures, and what the second pass costs.

1. Heights: the height calibration recorded with crossed lines (lines along y and at 45° to
   x; `record_height_calibration(cross=True)`) and fitted; its residuals per model; then the
   flat plate at 3 heights scanned crossed (Method 2) and the step block at 3 poses: |z −
   truth| of each pass's points (the step block's away from its walls: the true surface flat
   within ±0.5 mm around the point).
2. Cost: the step block's scan along y alone and crossed (0.5 and 1.0 mm apart): frames,
   points, seconds of the scan (CPU and wall; the machine may be shared).

Run: .venv/bin/python benchmarks/cross_scan.py [--binning 2] [--seed 0] [--cache DIR]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.formats.calibration import HeightCalibration
from insitu.formats.json_file import load_json_model, save_json_model
from insitu.services import calibrate_height, scan_live
from insitu.services.record import record_height_calibration
from insitu.services.station import simulated
from insitu.sim.rig import default_rig
from insitu.sim.scene import Scene
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld, sim_world

console = Console(width=150)
POSES = [(5.0, 3.0, 0.0), (-8.0, 6.0, 90.0), (3.0, -2.0, 33.0)]


def crossed_calibration(cache: Path, rig, seed: int) -> HeightCalibration:
    path = cache / "height-x.json"
    if not path.exists():
        record_height_calibration(simulated(SimWorld(rig, seed=seed)), cache / "hcal-x",
                                  cross=True)
        save_json_model(path, calibrate_height(cache / "hcal-x"))
    return load_json_model(path, HeightCalibration)


def passes(cloud) -> dict[str, np.ndarray]:
    """The cloud's points by pass: each line's direction from its points (along y, 45°)."""
    line = cloud.attributes["line"]
    out = {"along y": np.zeros(len(line), bool), "crossed 45°": np.zeros(len(line), bool)}
    for i in np.unique(line):
        sel = line == i
        xy = cloud.points[sel, :2]
        d = np.linalg.svd(xy - xy.mean(0), full_matrices=False)[2][0]
        a = np.degrees(np.arctan2(d[1], d[0])) % 180
        out["along y" if abs(a - 90) < 10 else "crossed 45°"][sel] = True
    return {k: cloud.points[v] for k, v in out.items()}


def true_z(scene: Scene, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The true surface height under each point, and whether it is flat within ±0.5 mm."""
    z = []
    for dx, dy in ((0, 0), (0.5, 0), (-0.5, 0), (0, 0.5), (0, -0.5)):
        rays = np.column_stack([p[:, 0] + dx, p[:, 1] + dy, np.full(len(p), 80.0)])
        z.append(scene.cast(rays, np.tile([0.0, 0.0, -1.0], (len(p), 1))).points[:, 2])
    z = np.array(z)
    return z[0], np.ptp(z, axis=0) < 1e-6


def heights_table(args, rig, cal) -> None:
    r = cal.residuals
    console.print(f"height calibration, binning {args.binning}: along y RMS "
                  f"{r['sheet_rms_mm']:.4f} mm (CV {r['sheet_cv_rms_mm']:.4f}), crossed RMS "
                  f"{r['sheet_cross_rms_mm']:.4f} mm (CV {r['sheet_cross_cv_rms_mm']:.4f}); "
                  f"max {r['sheet_max_mm']:.3f} / {r['sheet_cross_max_mm']:.3f} mm")
    tab = Table(title="|z − truth| of each pass's points, Method 2, mm (median / RMS / 99 %)")
    for c in ("surface", "points along y", "along y", "points crossed", "crossed 45°"):
        tab.add_column(c)
    for z0 in (-10.0, 0.0, 10.0):
        world = SimWorld(rig, seed=args.seed)
        with simulated(world) as station:
            world.clear_table()
            station.devices.stage.move_z(z0)
            cloud = scan_live(station, 1.0, (-25, 25, -40, 40), height_cal=cal, cross=True,
                              cross_spacing=1.0).cloud
        tab.add_row(f"plate at {z0:g} mm", *_cells({k: p[:, 2] - z0 for k, p in
                                                      passes(cloud).items()}))
    for pose in POSES:
        world = sim_world("step-block", seed=args.seed, rig=rig, pose=pose)
        with simulated(world) as station:
            cloud = scan_live(station, 0.5, height_cal=cal, cross=True).cloud
        scene = Scene([make_workpiece("table"),
                       make_workpiece("step-block", x=pose[0], y=pose[1], angle_deg=pose[2])])
        errs = {}
        for k, p in passes(cloud).items():
            z, flat = true_z(scene, p)
            errs[k] = (p[:, 2] - z)[flat]
        tab.add_row("step block at ({:g}, {:g}, {:g}°)".format(*pose), *_cells(errs))
    console.print(tab)


def _cells(errs: dict[str, np.ndarray]) -> list[str]:
    out = []
    for k in ("along y", "crossed 45°"):
        e = np.abs(errs[k])
        out += [f"{len(e):,}", f"{np.median(e):.3f} / {np.sqrt(np.mean(e ** 2)):.3f} / "
                               f"{np.percentile(e, 99):.3f}"]
    return out


def cost_table(args, rig, cal) -> None:
    tab = Table(title=f"scan cost, step block, binning {args.binning}, lines along y 0.5 mm "
                      "apart (the crossed pass over the same region)")
    for c in ("pose", "crossed pass", "frames", "points", "scan CPU s", "scan wall s"):
        tab.add_column(c)
    for pose in POSES:
        for cross in (None, 1.0, 0.5):
            world = sim_world("step-block", seed=args.seed, rig=rig, pose=pose)
            with simulated(world) as station:
                c0, t0 = time.process_time(), time.perf_counter()
                res = scan_live(station, 0.5, height_cal=cal, cross=bool(cross),
                                cross_spacing=cross)
                cpu, wall = time.process_time() - c0, time.perf_counter() - t0
            tab.add_row("({:g}, {:g}, {:g}°)".format(*pose),
                        "none" if cross is None else f"{cross:g} mm apart",
                        str(res.summary.frames), f"{len(res.cloud):,}", f"{cpu:.1f}",
                        f"{wall:.1f}")
    console.print(tab)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binning", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/insitu-cross-bench"))
    ap.add_argument("--skip", default="", help="comma-separated: heights, cost")
    args = ap.parse_args()
    skip = set(args.skip.split(","))
    cache = args.cache / f"b{args.binning}"
    cache.mkdir(parents=True, exist_ok=True)
    rig = default_rig(seed=args.seed, binning=args.binning)
    cal = crossed_calibration(cache, rig, args.seed)
    if "heights" not in skip:
        heights_table(args, rig, cal)
    if "cost" not in skip:
        cost_table(args, rig, cal)


if __name__ == "__main__":
    main()
