"""Measurement accuracy on the simulated rig (realistic calibration errors), full-size frames.

Li et al. §3.2: the step block (heights 3, 5, 10, 15 mm; lines every 0.5 mm): mean measured
height per step and the height error against y (their Fig. 5) for
  plane — Method 1 (light plane), the paper's gray centroid (k = 0.5);
  paper — Method 2 as the paper does it (P = P1 + P2), the paper's gray centroid;
  sheet — Method 2 with our light-sheet model, our centres (Steger, smoothed along the line);
and the
block's length from the first and last points of each line (paper: 79.900 ± 0.154 mm). Then
the same error table for the arc surface, the insert (thickness, hole, sides: the paper's
Table 1) and the freeform surface.

Run: .venv/bin/python benchmarks/accuracy.py [--seed N] [--parts step-block,arc,insert,freeform]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table
from scipy.spatial import cKDTree

from insitu.reconstruct.plan import scan_lines
from insitu.reconstruct.scan import ScanReconstructor
from insitu.services import calibrate_height, centre_settings, height_model
from insitu.services.record import record_height_calibration
from insitu.services.station import simulated
from insitu.sim.devices import SimCamera, SimScanHead
from insitu.sim.rig import default_rig
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld
from insitu.vision.extract import PAPER_SETTINGS, CentreSettings

console = Console(width=150)
METHODS = ("plane", "paper", "sheet")
WALL_MARGIN_MM = 1.0


def reconstruct(world: SimWorld, cals, region, spacing=0.5):
    """One pass over the scan; every frame goes to the three reconstructors."""
    rig = world.rig
    H = rig.operator.head.pivot_height_mm
    recs = {"plane": ScanReconstructor(rig.operator.camera, H, settings=PAPER_SETTINGS)}
    for name in ("paper", "sheet"):
        cam, model = height_model(cals[name], name)
        recs[name] = ScanReconstructor(cam, H, height_model=model,
                                       settings=centre_settings(cals[name]))
    cam, head = SimCamera(world), SimScanHead(world)
    t_rec = {m: 0.0 for m in METHODS}
    for i, (a, b) in enumerate(scan_lines(region, spacing)):
        head.show_line(a, b)
        frame = cam.grab()
        for m, rec in recs.items():
            t = time.perf_counter()
            rec.add(i, frame, a, b)
            t_rec[m] += time.perf_counter() - t
    head.off()
    return {m: r.cloud() for m, r in recs.items()}, t_rec


def on_top(part, p, margin=WALL_MARGIN_MM):
    """(N,) bool: points (N, ≥2) over the part's top at least ``margin`` mm from any edge or
    wall (the true height is the same all around them), and their true heights (N,)."""
    z_true = part.height(p[:, 0], p[:, 1])
    ok = np.isfinite(z_true)
    for dx, dy in ((margin, 0), (-margin, 0), (0, margin), (0, -margin)):
        zn = part.height(p[:, 0] + dx, p[:, 1] + dy)
        ok &= np.isfinite(zn) & (np.abs(zn - z_true) < 0.05 * margin + 0.3)
    return ok, z_true


def height_errors(part, cloud, margin=WALL_MARGIN_MM):
    """Points over the part's top ≥ ``margin`` mm from walls (N, 3), and their height error."""
    p = cloud.points
    ok, z_true = on_top(part, p, margin)
    return p[ok], p[ok, 2] - z_true[ok]


def step_block(world, clouds):
    part = world.parts[0]
    steps = Table(title="step block: mean measured height per step, mm (Li et al. Fig. 5a)")
    steps.add_column("step")
    for m in METHODS:
        steps.add_column(m)
    for h, (y0, y1) in zip((3, 5, 10, 15), ((-40, -20), (-20, 0), (0, 20), (20, 40))):
        row = [f"{h} mm"]
        for m in METHODS:
            p, e = height_errors(part, clouds[m])
            sel = (p[:, 1] > y0) & (p[:, 1] < y1)
            row.append(f"{np.mean(p[sel, 2]):.3f}")
        steps.add_row(*row)
    console.print(steps)
    prof = Table(title="step block: height error against y, mm: mean (max |e|) per 10 mm "
                       "(Li et al. Fig. 5b)")
    prof.add_column("y, mm")
    for m in METHODS:
        prof.add_column(m)
    for y0 in range(-40, 40, 10):
        row = [f"{y0} … {y0 + 10}"]
        for m in METHODS:
            p, e = height_errors(part, clouds[m])
            sel = (p[:, 1] >= y0) & (p[:, 1] < y0 + 10)
            row.append(f"{np.mean(e[sel]):+.3f} ({np.max(np.abs(e[sel])):.3f})")
        prof.add_row(*row)
    console.print(prof)
    length = Table(title="step block length from each line's first and last point on the block "
                         "(true 80 mm; paper 79.900 ± 0.154)")
    length.add_column("method")
    length.add_column("length, mm")
    for m in METHODS:
        c = clouds[m]
        p, line = c.points, c.attributes["line"]
        Ls = []
        for k in np.unique(line):
            q = p[(line == k) & (p[:, 2] > 1.5)]
            if len(q) > 50 and np.abs(np.median(q[:, 0])) < 8.0:  # lines well inside the block
                Ls.append(q[:, 1].max() - q[:, 1].min())
        length.add_row(m, f"{np.mean(Ls):.3f} ± {np.std(Ls):.3f}")
    console.print(length)


def insert_dimensions(world, clouds):
    """Thickness, hole diameter and side lengths from the top face's points (Table 1)."""
    part = world.parts[0]
    t = Table(title="insert: measured vs true (Li et al. Table 1: thickness 4.683, sides "
                    "16.055–16.069, hole 3.726 mm)")
    for col in ("method", "thickness", "hole D", "side 1", "side 2", "side 3"):
        t.add_column(col)
    t.add_row("true", f"{part.params.get('thickness', 4.68):.3f}",
              f"{part.params.get('hole_diameter', 3.8):.3f}", *["16.140"] * 3)
    for m in METHODS:
        p = clouds[m].points
        top = p[p[:, 2] > 2.34]
        thick = np.median(top[:, 2])
        r = np.hypot(top[:, 0], top[:, 1])
        ang = np.arctan2(top[:, 1], top[:, 0])
        bins = np.linspace(-np.pi, np.pi, 73)
        idx = np.digitize(ang, bins)
        hole = 2 * np.median([r[idx == i].min() for i in range(1, 73) if (idx == i).any()])
        sides = _triangle_sides(top[:, :2])
        t.add_row(m, f"{thick:.3f}", f"{hole:.3f}", *[f"{s:.3f}" for s in sides])
    console.print(t)


def _triangle_sides(xy):
    """Side lengths of the triangle the points fill: fit a line to the outermost points in
    each of the three side directions (normals at 180°, ±60°), intersect."""
    lines = []
    for a in np.deg2rad([180.0, 60.0, -60.0]):
        n = np.array([np.cos(a), np.sin(a)])
        d = xy @ n
        along = xy @ np.array([-n[1], n[0]])
        edge = []
        for lo in np.linspace(along.min(), along.max(), 40)[:-1]:
            sel = (along >= lo) & (along < lo + (along.max() - along.min()) / 39)
            if sel.sum() > 3:
                edge.append(xy[sel][np.argmax(d[sel])])
        edge = np.array(edge[5:-5])  # away from the rounded corners
        c = edge.mean(0)
        _, _, vt = np.linalg.svd(edge - c)
        lines.append((c, vt[0]))
    corners = []
    for i in range(3):
        (c1, d1), (c2, d2) = lines[i], lines[(i + 1) % 3]
        s = np.linalg.solve(np.column_stack([d1, -d2]), c2 - c1)
        corners.append(c1 + s[0] * d1)
    return [np.linalg.norm(corners[i] - corners[(i + 1) % 3]) for i in range(3)]


def coverage(part, cloud, step=0.25):
    """Fraction of the part's top (≥ 0.3 mm from walls) along the scanned lines that holds a
    measured point within ``step`` mm."""
    p, line = cloud.points, cloud.attributes["line"]
    xs = np.array([np.median(p[line == k, 0]) for k in np.unique(line)])
    lo, hi = part.bounds()
    gx, gy = (g.ravel() for g in np.meshgrid(xs, np.arange(lo[1], hi[1], step)))
    probe = np.column_stack([gx, gy])
    top, _ = on_top(part, probe, margin=0.3)
    d, _ = cKDTree(p[:, :2]).query(probe[top])
    return float(np.mean(d <= step))


def lateral_shift(part, p, e, h=0.05):
    """The cloud's constant shift (dx, dy) mm in x, y, fitted to the height errors ``e`` (N,)
    of its points ``p`` (N, 3) over the top as e ≈ −∇z_true · (dx, dy), and the RMS of what
    is left: the error a lateral offset of the whole cloud (the operator's camera
    calibration, shared with the placed patterns) makes on slopes (0 on flat tops)."""
    gx = (part.height(p[:, 0] + h, p[:, 1]) - part.height(p[:, 0] - h, p[:, 1])) / (2 * h)
    gy = (part.height(p[:, 0], p[:, 1] + h) - part.height(p[:, 0], p[:, 1] - h)) / (2 * h)
    ok = np.isfinite(gx) & np.isfinite(gy)
    A = np.column_stack([-gx[ok], -gy[ok]])
    c, *_ = np.linalg.lstsq(A, e[ok], rcond=None)
    return c, float(np.sqrt(np.mean((e[ok] - A @ c) ** 2)))


def error_table(title, parts_clouds):
    t = Table(title=title)
    for col in ("workpiece", "method", "points", "mean", "RMS", "max |e|", "RMS ≥0.3",
                "max ≥0.3", "top covered", "shift (x, y)", "RMS ≥0.3 unshifted"):
        t.add_column(col)
    for name, (world, clouds) in parts_clouds.items():
        part = world.parts[0]
        for m in METHODS:
            _, e = height_errors(part, clouds[m])
            p3, e3 = height_errors(part, clouds[m], margin=0.3)
            shift, rest = lateral_shift(part, p3, e3)
            t.add_row(name, m, f"{len(e):,}", f"{np.mean(e):+.4f}",
                      f"{np.sqrt(np.mean(e**2)):.4f}", f"{np.max(np.abs(e)):.4f}",
                      f"{np.sqrt(np.mean(e3**2)):.4f}", f"{np.max(np.abs(e3)):.4f}",
                      f"{coverage(part, clouds[m]):.1%}",
                      f"({shift[0]:+.3f}, {shift[1]:+.3f})", f"{rest:.4f}")
    console.print(t)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--parts", default="step-block,arc,insert,freeform")
    args = ap.parse_args()
    rig = default_rig(seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        hcal = Path(tmp) / "hcal"
        record_height_calibration(simulated(SimWorld(rig, seed=args.seed)), hcal)
        t1 = time.perf_counter()
        cals = {"paper": calibrate_height(hcal, PAPER_SETTINGS)}
        t2 = time.perf_counter()
        cals["sheet"] = calibrate_height(hcal, CentreSettings())
        console.print(f"height calibration: recorded in {t1 - t0:.1f} s, fitted in "
                      f"{time.perf_counter() - t2:.1f} s")
        for name, cal in cals.items():
            console.print(f"  residuals with {name} centres: " + ", ".join(
                f"{k} {v:.4f}" for k, v in cal.residuals.items() if k.endswith("mm")))
    results = {}
    spacing = {"insert": 0.2}
    for name in args.parts.split(","):
        world = SimWorld(rig, parts=[make_workpiece(name)], seed=args.seed + 1)
        lo, hi = world.parts[0].bounds()
        region = (lo[0] - 3, hi[0] + 3, lo[1] - 6, hi[1] + 6)
        clouds, t_rec = reconstruct(world, cals, region, spacing.get(name, 0.5))
        n = len(scan_lines(region, spacing.get(name, 0.5)))
        console.print(f"{name}: {n} frames; reconstruction per frame: "
                      + ", ".join(f"{m} {1000 * t / n:.1f} ms" for m, t in t_rec.items()))
        results[name] = (world, clouds)
    error_table(f"height error over the parts' tops ≥ {WALL_MARGIN_MM} mm from walls, mm",
                results)
    if "step-block" in results:
        step_block(*results["step-block"])
    if "insert" in results:
        insert_dimensions(*results["insert"])


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
