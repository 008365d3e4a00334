"""Marking accuracy and speed on the simulated rig (realistic calibration errors, binning 2).

1. placement — patterns placed at a requested centre and width on the step block's steps
   (planar): the job's centre and width against the request; then the job marked by the sim
   head (uncorrected, and with an ideal field correction built from the simulator's truth as
   a stand-in for FIELD.json), imaged by the sim camera and measured (find_marks).
2. focus — every job point's z against the true surface height at its x, y, on clouds the
   simulator measured (scan_live with a height calibration) of the step block and the arc.
3. wrap — 30 mm lines and a square wrapped on the measured arc: length along the TRUE surface
   against the pattern's length (< 0.5 %), and the reported stretch.
4. speed — a 30 × 30 mm QR-like grid of filled squares hatched at 0.04 mm, projected onto a
   2-million-point cloud and made into a job (< 2 s).

Run: .venv/bin/python benchmarks/marking_accuracy.py [--seed N] [--binning 2] [--skip-inspection]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.errors import SafetyError
from insitu.marking import (
    GalvoDriver,
    Limits,
    Placement,
    check_projection,
    estimate_time,
    make_job,
    plan_job,
    project,
    run_job,
    write_job,
)
from insitu.marking.project import densify
from insitu.services import calibrate_height
from insitu.services.mark import check_codes
from insitu.services.record import record_height_calibration
from insitu.services.scan import scan_live
from insitu.services.station import simulated
from insitu.sim.controller import SimController
from insitu.sim.marks import find_marks, render_inspection
from insitu.sim.rig import default_rig
from insitu.sim.world import SimWorld, sim_world

console = Console(width=150)
STEPS = ((3.0, -30.0), (5.0, -10.0), (10.0, 10.0), (15.0, 30.0))   # (height, y of its centre)


def unit_pattern() -> list[np.ndarray]:
    """A square outline with a cross inside, centred on 0, 1 wide."""
    sq = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5]])
    return [sq, np.array([[-0.3, 0.0], [0.3, 0.0]]), np.array([[0.0, -0.3], [0.0, 0.3]])]


def place(polys, centre, width) -> list[np.ndarray]:
    return [np.asarray(centre) + width * p for p in polys]


def scan_clouds(seed: int, binning: int):
    rig = default_rig(seed=seed, binning=binning)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        record_height_calibration(simulated(SimWorld(rig, seed=seed)), Path(tmp) / "hcal")
        cal = calibrate_height(Path(tmp) / "hcal")
        console.print(f"height calibration recorded and fitted in {time.perf_counter() - t:.1f} s")
    worlds, clouds = {}, {}
    for name in ("step-block", "arc"):
        t = time.perf_counter()
        worlds[name] = sim_world(name, seed=seed, rig=rig)
        clouds[name] = scan_live(simulated(worlds[name]), height_cal=cal).cloud
        console.print(f"{name}: {len(clouds[name])} points measured in "
                      f"{time.perf_counter() - t:.1f} s")
    return rig, worlds, clouds


def measure_square(xy: np.ndarray, centre, width, band=2.0):
    """Centre x, y and width, height of a marked square from points on its sides (mark
    pixels or burn samples): each side's median position."""
    cx, cy, h = centre[0], centre[1], width / 2
    side = []
    for axis, sign in ((0, -1), (0, 1), (1, -1), (1, 1)):
        other = 1 - axis
        sel = ((np.abs(xy[:, axis] - ((cx, cy)[axis] + sign * h)) < band)
               & (np.abs(xy[:, other] - (cx, cy)[other]) < h - band))
        side.append(np.median(xy[sel, axis]) if sel.sum() > 10 else np.nan)
    left, right, bottom, top = side
    return (left + right) / 2, (bottom + top) / 2, right - left, top - bottom


def _fmt(m, centre, width) -> list[str]:
    mx, my, mw, mh = m
    if not np.isfinite([mx, my, mw, mh]).all():
        return ["(not found)", "-"]
    return [f"({mx - centre[0]:+.3f}, {my - centre[1]:+.3f})", f"{mw - width:+.3f} / {mh - width:+.3f}"]


def placement_table(title, rig, world, cloud, cases, inspect: bool) -> None:
    """cases: (label, centre (2,), width). Job, burnt (sim truth) and inspected (camera)."""
    limits = Limits.of(rig.operator.head)
    tab = Table(title=title)
    for col in ("where", "job Δcentre", "job Δwidth", "burnt Δcentre uncorrected", "Δwidth x / y",
                "burnt Δcentre corrected", "Δwidth x / y", "inspected Δcentre corrected",
                "Δwidth x / y"):
        tab.add_column(col)
    for label, centre, width in cases:
        centre = np.asarray(centre, float)
        job, proj = plan_job(place(unit_pattern(), centre, width), cloud, limits)
        pts = proj.points
        lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
        dc = 0.5 * (lo + hi) - centre
        row = [label, f"({dc[0]:+.4f}, {dc[1]:+.4f})", f"{(hi[0] - lo[0]) - width:+.4f}"]
        for corr in (None, rig.ideal_correction()):
            sc = SimController(world)
            run_job(job, GalvoDriver.from_config(rig.operator.head, corr), sc)
            burnt = np.vstack([b.points for b in sc.burns])[:, :2]
            row += _fmt(measure_square(burnt, centre, width), centre, width)
        if inspect:
            img = render_inspection(rig, sc.scene, sc.burns, seed=1)
            xy, _ = find_marks(img, rig.operator.camera, float(np.median(pts[:, 2])),
                               kernel_px=11)
            row += _fmt(measure_square(xy, centre, width), centre, width)
        else:
            row += ["-", "-"]
        tab.add_row(*row)
    console.print(tab)


def placement(rig, world, cloud, inspect: bool) -> None:
    placement_table("placement on the measured step block (planar, 12 mm square + cross), mm: "
                    "job; burnt (sim truth); inspected (sim camera, operator calibration)",
                    rig, world, cloud,
                    [(f"{h:g} mm step", (0.0, yc), 12.0) for h, yc in STEPS], inspect)
    g = np.arange(-100.0, 100.01, 0.25)
    X, Y = np.meshgrid(g, g)
    flat = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    placement_table("placement across the field (table, z = 0; synthetic flat cloud), 20 mm "
                    "square, mm", rig, SimWorld(rig, seed=rig.seed), flat,
                    [(f"({x:g}, {y:g})", (x, y), 20.0)
                     for x, y in ((0, 0), (60, 60), (-60, 55), (55, -60), (-70, -70))], inspect)


def focus(worlds, clouds, rig) -> None:
    limits = Limits.of(rig.operator.head)
    tab = Table(title="focus: job z − true surface z at the job's x, y, mm (limit 0.1)")
    for col in ("surface", "pattern", "mode", "points", "mean", "RMS", "max |e|", "ok"):
        tab.add_column(col)
    cases = [("step-block", f"12 mm on the {h:g} mm step", (0.0, yc), 12.0, "planar")
             for h, yc in STEPS]
    cases += [("arc", "20 mm at the apex", (0.0, 0.0), 20.0, "planar"),
              ("arc", "30 mm", (0.0, 0.0), 30.0, "planar"),
              ("arc", "30 mm", (0.0, 0.0), 30.0, "wrap"),
              ("arc", "16 mm off centre", (8.0, -6.0), 16.0, "wrap")]
    for name, label, c, w, mode in cases:
        part = worlds[name].parts[0]
        polys = place(unit_pattern(), np.array(c), w)
        job, proj = plan_job(polys, clouds[name], limits, mode=mode)
        p = proj.points
        e = p[:, 2] - part.height(p[:, 0], p[:, 1])
        ok = np.abs(e).max() < 0.1
        tab.add_row(name, label, mode, str(len(p)), f"{e.mean():+.4f}",
                    f"{np.sqrt(np.mean(e**2)):.4f}", f"{np.abs(e).max():.4f}",
                    "[green]yes[/]" if ok else "[red]no[/]")
    qr = Placement('qr:"insitu"', (0.0, -20.0), 10.0, mode="planar")     # issue 11
    pattern = qr.placed()
    job, qr_proj = plan_job(qr.polylines(pattern), clouds["step-block"], limits, mode="planar")
    code = check_codes(job, pattern, qr_proj, qr.beam_mm)[0]
    p = np.vstack([path.points for path in job.paths])                   # laser on
    e = p[:, 2] - worlds["step-block"].parts[0].height(p[:, 0], p[:, 1])
    wall = np.abs(p[:, 1] + 20.0)                                        # the wall at y = −20
    for label, sel in (("", wall >= 0), (", > 0.25 mm from the wall", wall > 0.25)):
        tab.add_row("step-block", f"10 mm QR across the 3/5 mm edge{label}", "planar",
                    str(sel.sum()), f"{e[sel].mean():+.4f}",
                    f"{np.sqrt(np.mean(e[sel]**2)):.4f}", f"{np.abs(e[sel]).max():.4f}",
                    "[green]yes[/]" if np.abs(e[sel]).max() < 0.1 else "[red]no[/]")
    console.print(tab)
    off = np.abs(e) > 0.1
    if off.any():
        console.print(f"QR across the edge: {off.sum()} of {len(e)} marked points more than "
                      f"0.1 mm off, all within {wall[off].max():.2f} mm of the wall")
    console.print(f"QR across the edge: unmarked at the wall {qr_proj.unmarked_mm:.2f} of "
                  f"{qr_proj.path_mm:.0f} mm of path ({qr_proj.unmarked_fraction:.1%}), marked "
                  f"{wall[p[:, 1] < -20.0].min():.3f} mm below and {wall[p[:, 1] > -20.0].min():.3f}"
                  f" mm above the wall; decodes {'yes' if code.ok else 'NO'}")


def true_length(part, xyz: np.ndarray) -> float:
    """Length of the job polyline's x, y track on the TRUE surface, mm (sampled at 10 µm)."""
    (xy,) = densify([xyz[:, :2]], 0.01)
    z = part.height(xy[:, 0], xy[:, 1])
    return float(np.linalg.norm(np.diff(np.column_stack([xy, z]), axis=0), axis=1).sum())


def wrap(worlds, clouds, rig) -> None:
    part, cloud = worlds["arc"].parts[0], clouds["arc"]
    limits = Limits.of(rig.operator.head)
    tab = Table(title="wrap on the measured arc: length along the true surface vs the "
                      "pattern's (limit 0.5 %)")
    for col in ("pattern", "length", "true-surface length", "error", "job polyline length",
                "max stretch", "direction"):
        tab.add_column(col)
    sq = np.array([[-12.0, -12], [12, -12], [12, 12], [-12, 12], [-12, -12]])
    cases = [("30 mm across the axis", [np.array([[-15.0, 0.0], [15.0, 0.0]])]),
             ("30 mm across, off centre", [np.array([[-14.0, 8.0], [16.0, 8.0]])]),
             ("30 mm along the axis", [np.array([[3.0, -15.0], [3.0, 15.0]])]),
             ("30 mm diagonal", [np.array([[-10.6, -10.6], [10.6, 10.6]])]),
             ("24 mm square (4 sides)", [sq[i:i + 2] for i in range(4)])]
    for label, polys in cases:
        centre = 0.5 * (np.vstack(polys).min(0) + np.vstack(polys).max(0))
        proj = project(polys, cloud, "wrap", anchor=centre)
        check_projection(proj, limits)
        L0 = sum(float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in polys)
        Lt = sum(true_length(part, p) for p in proj.paths)
        Lj = sum(float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in proj.paths)
        err = (Lt - L0) / L0 * 100
        tab.add_row(label, f"{L0:.3f}", f"{Lt:.3f}",
                    f"[{'green' if abs(err) < 0.5 else 'red'}]{err:+.3f} %[/]",
                    f"{Lj:.3f}", f"{proj.max_stretch * 100:.3f} %", f"{proj.direction_deg:.0f}°")
    console.print(tab)


def qr_hatch(size=30.0, modules=25, pitch=0.04, seed=0) -> list[np.ndarray]:
    """A QR-like grid of filled squares, hatched along x every ``pitch`` mm, centred on 0."""
    rng = np.random.default_rng(seed)
    grid = rng.random((modules, modules)) < 0.5
    for r, c in ((0, 0), (0, modules - 7), (modules - 7, 0)):      # finder squares
        grid[r:r + 7, c:c + 7] = True
    m = size / modules
    lines = []
    for i, y in enumerate(np.arange(-size / 2 + pitch / 2, size / 2, pitch)):
        row = grid[min(int((y + size / 2) // m), modules - 1)]
        d = np.diff(np.concatenate([[0], row.astype(int), [0]]))
        for s, e in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
            a, b = [-size / 2 + s * m, y], [-size / 2 + e * m, y]
            lines.append(np.array([a, b] if i % 2 == 0 else [b, a]))
    return lines


def speed(rig, repeats=3) -> None:
    rng = np.random.default_rng(0)
    xs, ys = np.arange(-50, 50, 0.1), np.arange(-50, 50, 0.05)            # 1000 × 2000 lines
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    Z = 6 + 2.5 * np.sin(2 * np.pi * X / 50) * np.cos(2 * np.pi * Y / 60)
    cloud = np.column_stack([X.ravel(), Y.ravel(), Z.ravel() + rng.normal(0, 0.01, X.size)])
    lines = qr_hatch()
    limits = Limits.of(rig.operator.head)
    tab = Table(title=f"speed: QR-like 30 × 30 mm, hatched at 0.04 mm ({len(lines)} lines, "
                      f"{sum(np.linalg.norm(line[1] - line[0]) for line in lines):.0f} mm) "
                      f"on a {len(cloud) / 1e6:.1f}-million-point cloud, s")
    for col in ("run", "project", "check", "make job", "→ job total", "points", "estimate",
                "write JSON", "compile commands"):
        tab.add_column(col)
    for r in range(repeats):
        t0 = time.perf_counter()
        proj = project(lines, cloud, "planar")
        t1 = time.perf_counter()
        check_projection(proj, limits)
        t2 = time.perf_counter()
        job = make_job(proj.paths)
        t3 = time.perf_counter()
        est = estimate_time(job)
        t4 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            write_job(Path(tmp) / "job.json", job)
        t5 = time.perf_counter()
        GalvoDriver.from_config(rig.operator.head).compile(job)
        t6 = time.perf_counter()
        total = t3 - t0
        tab.add_row(str(r + 1), f"{t1 - t0:.3f}", f"{t2 - t1:.3f}", f"{t3 - t2:.3f}",
                    f"[{'green' if total < 2 else 'red'}]{total:.3f}[/]", str(len(proj.points)),
                    f"{t4 - t3:.3f} ({est.total_s:.1f} s to mark)", f"{t5 - t4:.3f}",
                    f"{t6 - t5:.3f}")
    console.print(tab)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--binning", type=int, default=2)
    ap.add_argument("--skip-inspection", action="store_true")
    ap.add_argument("--only-speed", action="store_true")
    args = ap.parse_args()
    if args.only_speed:
        speed(default_rig(seed=args.seed, binning=args.binning))
        return
    rig, worlds, clouds = scan_clouds(args.seed, args.binning)
    try:
        placement(rig, worlds["step-block"], clouds["step-block"], not args.skip_inspection)
        focus(worlds, clouds, rig)
        wrap(worlds, clouds, rig)
    except SafetyError as e:
        console.print(f"[red]refused:[/] {e}")
    speed(rig)


if __name__ == "__main__":
    main()
