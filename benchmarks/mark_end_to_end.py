"""End to end on the simulated rig: calibrate, scan, place, mark, image — do the marks land on
the design?

1. Field calibration: 2 mm circles marked uncorrected on the plate (21 × 21 over ±90 mm),
   imaged, fitted (RBF) → the FIELD.json an operator would have. Height calibration recorded
   and fitted. Both through the same code as `insitu calibrate field` / `height`.
2. Scan the step block and the arc with the height calibration (Method 2).
3. Place a 10 mm QR code across the edge between the 3 mm and 5 mm steps (planar) and a
   20 mm logo on the arc (wrap), hatched at 0.3 mm, through `services.mark.plan_mark`.
4. Mark on the sim head with no correction, with the fitted FIELD.json, and with the flawless
   correction from the truth; then
   - burnt: where the true beam burnt the true part (the simulator's truth), each burn sample
     against the job's own path, and
   - inspected: the camera's image of the marked part, dark pixels back-projected through the
     operator's camera onto the measured surface, against the nearest design point — what
     the rig itself sees, in its own frame.
   Rows (x, y, mm): mean offset; the worst mean offset over 3 × 3 cells of the pattern (the
   placement error, free of the mark's width); the 95th percentile of |offset|.

Run: .venv/bin/python benchmarks/mark_end_to_end.py [--seed N] [--binning 2]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table
from scipy.spatial import cKDTree

from insitu.marking import GalvoDriver, Placement, run_job
from insitu.marking.project import densify
from insitu.marking.surface import Surface
from insitu.services import calibrate_height
from insitu.services.field import calibrate_field
from insitu.services.plan import plan_mark
from insitu.services.record import record_height_calibration, record_marked_field_calibration
from insitu.services.scan import scan_live
from insitu.services.station import simulated
from insitu.sim.controller import SimController
from insitu.sim.devices import SimInspectionCamera
from insitu.sim.marks import find_marks
from insitu.sim.rig import default_rig
from insitu.sim.world import SimWorld, sim_world

console = Console(width=150)
ROOT = Path(__file__).resolve().parents[1]
CASES = (("step-block", "10 mm QR across the 3/5 mm step edge",
          Placement('qr:"insitu"', (0.0, -20.0), 10.0, mode="planar", hatch_mm=0.3)),
         ("arc", "20 mm logo wrapped on the arc",
          Placement(str(ROOT / "patterns" / "logo.svg"), (0.0, 0.0), 20.0, mode="wrap",
                    hatch_mm=0.3)))


def burnt_errors(job, burns) -> tuple[np.ndarray, np.ndarray]:
    """Burn samples (M, 2) x, y mm, and their offset (M, 2) from the nearest point of their
    own path (burn i is path i), mm."""
    at, err = [], []
    for path, burn in zip(job.paths, burns):
        b = burn.points[np.isfinite(burn.points).all(1), :2]
        xy = path.points[:, :2]
        design = np.vstack(densify([xy], 0.002)) if len(xy) > 1 else xy
        _, i = cKDTree(design).query(b)
        at.append(b)
        err.append(b - design[i])
    return np.vstack(at), np.vstack(err)


def inspected_errors(world, job, cloud) -> tuple[np.ndarray, np.ndarray]:
    """Dark pixels on the measured surface (M, 2) x, y mm, and their offset (M, 2) from the
    nearest design point, mm."""
    img = SimInspectionCamera(world).grab()
    design = np.vstack([np.vstack(densify([p.points], 0.005)) for p in job.paths])
    z0 = float(np.median(design[:, 2]))
    xy, _ = find_marks(img, world.rig.operator.camera, z0, kernel_px=9)
    lo, hi = design[:, :2].min(0) - 1.0, design[:, :2].max(0) + 1.0
    xy = xy[((xy >= lo) & (xy <= hi)).all(1)]
    surf = Surface(cloud, region=(lo[0] - 3, hi[0] + 3, lo[1] - 3, hi[1] + 3))
    # the pixels' rays meet the measured surface: iterate plane height → surface height
    uv = world.rig.operator.camera.project(np.column_stack([xy, np.full(len(xy), z0)]))
    o, d = world.rig.operator.camera.rays(uv)
    z = np.full(len(xy), z0)
    for _ in range(4):
        p = o[:2] + ((z - o[2]) / d[:, 2])[:, None] * d[:, :2]
        z = np.nan_to_num(surf.sample(p).z, nan=z0)
    _, i = cKDTree(design[:, :2]).query(p)
    return p, p - design[i, :2]


def row(label: str, at: np.ndarray, err: np.ndarray) -> list[str]:
    """Samples, mean offset, the worst mean offset of the 3 × 3 cells of the pattern's extent
    (placement error, free of the mark's width), 95th percentile of |offset|."""
    m = err.mean(0)
    lo, hi = at.min(0), at.max(0) + 1e-9
    cell = np.floor(3 * (at - lo) / (hi - lo)).astype(int) @ [1, 3]
    worst = max(np.linalg.norm(err[cell == c].mean(0)) for c in np.unique(cell)
                if (cell == c).sum() >= 20)
    return [label, f"{len(err):,}", f"({m[0]:+.3f}, {m[1]:+.3f})", f"{worst:.3f}",
            f"{np.percentile(np.linalg.norm(err, axis=1), 95):.3f}"]


def plan_note(label: str, plan, world) -> None:
    """One line on the plan: every job point's height against the true surface, the share of
    the pattern left unmarked at walls and whether its code decodes from the planned marks."""
    p = plan.projection.points
    e = np.abs(p[:, 2] - world.parts[0].height(p[:, 0], p[:, 1]))
    codes = "".join(f", decodes {'yes' if c.ok else 'NO'}" for c in plan.codes)
    pr = plan.projection
    console.print(f"{label}: {len(p)} job points, max |z − true surface| {e.max():.3f} mm; "
                  f"unmarked at walls {pr.unmarked_mm:.2f} of {pr.path_mm:.0f} mm of path "
                  f"({pr.unmarked_fraction:.1%}){codes}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--binning", type=int, default=2)
    args = ap.parse_args()
    rig = default_rig(seed=args.seed, binning=args.binning)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        record_marked_field_calibration(simulated(SimWorld(rig, seed=args.seed)), Path(tmp) / "field")
        field = calibrate_field(Path(tmp) / "field", "rbf")
        record_height_calibration(simulated(SimWorld(rig, seed=args.seed)), Path(tmp) / "hcal")
        height = calibrate_height(Path(tmp) / "hcal")
    console.print(f"field (marked circles, CV RMS {field.residuals['cv_rms_mm']:.4f} mm) and "
                  f"height calibrations recorded and fitted in {time.perf_counter() - t:.1f} s")
    corrections = (("uncorrected", None), ("FIELD.json (fitted)", field.correct),
                   ("flawless (truth)", rig.ideal_correction()))
    tab = Table(title="marks against the design (x, y), mm: burnt = the simulator's truth (beam "
                      "centre vs its own path); inspected = dark pixels of the rig's camera on "
                      "the measured surface (0.3 mm wide marks) vs the nearest design point")
    for c in ("case", "correction", "measured by", "samples", "mean offset (x, y)",
              "worst cell offset", "95 % |e|"):
        tab.add_column(c)
    for part, label, placement in CASES:
        world = sim_world(part, seed=args.seed, rig=rig)
        cloud = scan_live(simulated(world), height_cal=height).cloud
        for name, corr in corrections:
            world.burns.clear()
            driver = GalvoDriver.from_config(rig.operator.head, corr)
            plan = plan_mark(cloud, placement, driver, force=True)   # the verdict is printed
            if corr is None:
                plan_note(label, plan, world)
            run_job(plan.job, driver, SimController(world))
            tab.add_row(label, name, *row("burnt", *burnt_errors(plan.job, world.burns)))
            tab.add_row("", "", *row("inspected", *inspected_errors(world, plan.job, cloud)))
        tab.add_section()
    console.print(tab)


if __name__ == "__main__":
    main()
