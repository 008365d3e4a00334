"""Scan-field correction on the simulated head (Mikkelstrup et al. Table 1; Le & Quinsat §6).

The default rig's head lands ~0.8 mm RMS / ~2.5 mm max off over ±90 mm. A 21 × 21 = 441-spot
field calibration is recorded (full-size frames unless --binning), and fitted by
``calibrate_field`` (timed: reading frames, finding spots, training with 5-fold CV) with the
RBF network and with the correction table; and the marked-fiducial variant: 2 mm circles
marked uncorrected on the plate at the same commands, imaged once, fitted with the RBF network.
Validation on other positions (a 20 × 20 grid
offset by half a pitch): the corrected commands are sent to the simulated head, each spot frame
is rendered through the sim camera and detected, and its landing point measured with the
operator's camera (the rig's own frame) — and, from the truth, where the beam really landed
(the head's true frame: the difference is what the camera's own calibration error adds).

Run: .venv/bin/python benchmarks/field_correction.py [--seed N] [--binning 1|2|4] [--n 21]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.calibrate.field_areas import area_table, stats
from insitu.errors import CalibrationError
from insitu.formats.sequence import Sequence
from insitu.services.field import calibrate_field, measure_spots, report_png
from insitu.services.record import record_field_calibration, record_marked_field_calibration
from insitu.services.station import simulated
from insitu.sim.devices import SimCamera, SimScanHead, SimStage
from insitu.sim.rig import default_rig
from insitu.sim.world import SimWorld
from insitu.vision.spots import find_spot

console = Console(width=150)


def measure(world: SimWorld, commands: np.ndarray) -> np.ndarray:
    """Where each command's spot lands as the operator's camera sees it, (N, 2) mm on z = 0
    (NaN where the spot is not seen)."""
    cam, head = SimCamera(world), SimScanHead(world)
    op = world.rig.operator.camera
    out = np.full_like(commands, np.nan)
    for i, c in enumerate(commands):
        head.show_spot(c)
        try:
            uv = find_spot(cam.grab()).uv
        except CalibrationError:
            continue
        o, d = op.rays(uv[None])
        out[i] = o[:2] + (0.0 - o[2]) / d[0, 2] * d[0, :2]
    head.off()
    return out


def row(name: str, err: np.ndarray) -> list[str]:
    s = stats(err)
    return [name, str(s.n), *(f"{v:.4f}" for v in s.rms_mm), *(f"{v:.4f}" for v in s.max_mm)]


def error_table(title: str) -> Table:
    t = Table(title=title)
    for c in ("", "n", "RMS ux", "RMS uy", "RMS |δ|", "max ux", "max uy", "max |δ|"):
        t.add_column(c, justify="right" if c else "left")
    return t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--binning", type=int, default=1)
    ap.add_argument("--n", type=int, default=21, help="calibration spots per side")
    ap.add_argument("--half", type=float, default=90.0, help="calibration half field, mm")
    ap.add_argument("--keep", type=Path, default=None, help="keep the recording and reports here")
    ap.add_argument("--reuse", action="store_true",
                    help="with --keep: use the recording already there (same seed, binning, n)")
    args = ap.parse_args()

    rig = default_rig(args.seed, binning=args.binning)
    world = SimWorld(rig, seed=args.seed)
    tmp = Path(args.keep or tempfile.mkdtemp(prefix="field-bench-"))
    tmp.mkdir(parents=True, exist_ok=True)
    rec = tmp / "field-rec"
    t0 = time.perf_counter()
    if not (args.reuse and (rec / "sequence.json").is_file()):
        record_field_calibration(simulated(world), rec, n=args.n, half_mm=args.half)
    console.print(f"recorded {args.n}×{args.n} spots, {rig.camera.width}×{rig.camera.height} px "
                  f"(binning {args.binning}), seed {args.seed}: {time.perf_counter() - t0:.1f} s "
                  f"→ {rec}")

    marked = tmp / "field-marked"
    t0 = time.perf_counter()
    if not (args.reuse and (marked / "sequence.json").is_file()):
        record_marked_field_calibration(simulated(SimWorld(rig, seed=args.seed)), marked, n=args.n,
                                        half_mm=args.half)
    console.print(f"marked and imaged {args.n}×{args.n} circles: {time.perf_counter() - t0:.1f} s")

    pitch = 2 * args.half / (args.n - 1)
    g = np.arange(-args.half + pitch / 2, args.half, pitch)
    Q = np.array([(x, y) for y in g for x in g])
    true_before = rig.beams.landing(Q) - Q
    SimStage(world).move_z(0.0)
    cam_before = measure(world, Q) - Q
    seen = np.isfinite(cam_before).all(1)

    t0 = time.perf_counter()
    measure_spots(Sequence.open(rec))
    t_measure = time.perf_counter() - t0
    results, summary = {}, Table(title=f"calibration of {args.n}×{args.n} spots: read, detect, "
                                       f"train + 5-fold CV (of which reading and detecting: "
                                       f"{t_measure:.1f} s)")
    for c in ("method", "time s", "spots", "model", "CV RMS |δ| mm", "CV fold RMS mm"):
        summary.add_column(c)
    for name, method, folder in (("rbf", "rbf", rec), ("table", "table", rec),
                                 ("rbf, marked circles", "rbf", marked)):
        t0 = time.perf_counter()
        cal = calibrate_field(folder, method)
        dt = time.perf_counter() - t0
        report_png(cal, tmp / f"field-{name.replace(', ', '-').replace(' ', '-')}.png")
        r = cal.residuals
        model = (f"σ {cal.rbf.sigma_mm:g} mm, goal {cal.rbf.mse_goal_mm2:g} mm², "
                 f"{len(cal.rbf.centres_mm)} neurons" if method == "rbf" else
                 f"{len(cal.table.x_nodes_mm)}×{len(cal.table.y_nodes_mm)} nodes, "
                 f"smoothing {cal.table.smoothing:g}")
        summary.add_row(name, f"{dt:.1f}", f"{int(r['points'])} ({int(r['spots_skipped'])} "
                        "not seen)", model, f"{r['cv_rms_mm']:.4f}",
                        f"{r['cv_fold_rms_mean_mm']:.4f} ± {r['cv_fold_rms_std_mm']:.4f}")
        K = cal.correct(Q)
        results[name] = (cal, rig.beams.landing(K) - Q, measure(world, K) - Q)
    console.print(summary)

    x0, x1, y0, y1 = results["rbf"][0].region_mm
    cal_q = np.array(results["rbf"][0].commands_mm)
    # validation targets with measured calibration spots all around (inside their hull)
    from scipy.spatial import Delaunay
    inside = Delaunay(cal_q).find_simplex(Q) >= 0

    t = error_table(f"validation, {len(Q)} targets (20 × 20, offset half a pitch), mm — "
                    "measured with the camera (the rig's own frame)")
    t.add_row(*row("uncorrected", cam_before[seen]))
    for method, (_, _, cam_err) in results.items():
        ok = np.isfinite(cam_err).all(1)
        t.add_row(*row(f"{method}", cam_err[ok]))
    console.print(t)
    t = error_table("validation in the scan head's TRUE frame (landing(K) − Q), mm")
    t.add_row(*row("uncorrected, all", true_before))
    for method, (_, true_err, _) in results.items():
        t.add_row(*row(f"{method}, seen by the camera", true_err[seen]))
        t.add_row(*row(f"{method}, inside the calibrated hull", true_err[inside]))
        t.add_row(*row(f"{method}, all (extrapolated outside)", true_err))
    console.print(t)

    half = 0.5 * max(x1 - x0, y1 - y0)
    for method, (_, _, cam_err) in results.items():
        ok = np.isfinite(cam_err).all(1)
        t = error_table(f"Table 1 style, {method}: camera-measured landing error per area, mm")
        for label, e in (("before", cam_before), ("after", cam_err)):
            for s in area_table(Q[ok & seen], e[ok & seen], half):
                t.add_row(f"{label} {s.name}", str(s.n), *(f"{v:.4f}" for v in s.rms_mm),
                          *(f"{v:.4f}" for v in s.max_mm))
        console.print(t)
    console.print(f"reports: {tmp}/field-rbf.png, {tmp}/field-table.png")


if __name__ == "__main__":
    main()
