"""The produce part of benchmarks/production.py (run by it, or alone) — production on the
simulated rig, no hand on the keyboard: a recipe marked on N parts, each
put on the table at a random pose, located, marked and read back — and a camera fault injected
at one part, the run resumed from its log.

1. The station as an operator has it: the field correction fitted from marked circles and the
   height calibration (Method 2), through the same services as `insitu calibrate field` /
   `height`; the recipe's reference is the part's mesh (as `insitu sim export-part` writes).
2. `produce` (services.production, as `insitu produce RECIPE --random-poses SEED --no-wait`):
   the camera stops delivering frames during the scan of part --fault-at; the run ends with
   the laser off and that part logged as a fault; a second run with --resume finishes it.
3. Per part: the located pose against the truth; where the code was marked on the part
   against the recipe's place (the simulator's burns, in the part's frame, against the
   planned marks' box: the placement error); the read-back (decoded = planned, grade, offset
   of the mark against the plan as the camera measures it); the time per stage.
4. The log: every part's last record "marked", serials 1 … N each issued exactly once (the
   counter and the log agree), the faulted part without a serial.

Run: .venv/bin/python benchmarks/production_run.py [--count 20] [--binning 2] [--seed 1]
     [--fault-at 7] [--module 0.35] [--spacing 0.25] [--cross 0.5] [--no-second-look]
     (or benchmarks/production.py, which runs it last)
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.calibrate.field_file import save_field_correction
from insitu.errors import DeviceError
from insitu.formats.counter import read_counter
from insitu.formats.mesh import write_mesh
from insitu.formats.production_log import read_log
from insitu.formats.recipe import Recipe, RecipeScan, write_recipe
from insitu.geometry.pose import flat_pose
from insitu.marking import Placement
from insitu.patterns.fields import Variables
from insitu.services import calibrate_height, production
from insitu.services.field import calibrate_field
from insitu.services.height import scan_camera
from insitu.services.locate import recipe_locator
from insitu.services.part_reading import read_part
from insitu.services.record import record_height_calibration, record_marked_field_calibration
from insitu.services.serials import render_placement
from insitu.services.station import connect, simulated
from insitu.sim.marks import burnt_centre
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld, sim_world

console = Console(width=160)
PART = "step-block"
AT = (0.0, -30.0)           # on the 3 mm step, part frame


def calibrations(folder: Path, seed: int, binning: int):
    """(field correction file, height calibration) fitted from simulated recordings (the
    height calibration with crossed lines, as `insitu record height-calibration` records it:
    for a crossed scan, or a second look)."""
    rig = sim_world(PART, seed=seed, binning=binning).rig
    record_marked_field_calibration(simulated(SimWorld(rig, seed=seed)), folder / "field")
    field = folder / "field.json"
    save_field_correction(field, calibrate_field(folder / "field", "rbf"))
    record_height_calibration(simulated(SimWorld(rig, seed=seed)), folder / "hcal", cross=True)
    return field, calibrate_height(folder / "hcal")


def placement(module_mm: float) -> Placement:
    return Placement('qr:"{serial:05d}";ec=M', AT, 21 * module_mm, 20.0)


def truth_offset(world, T_world_part, p: Placement, serial: int) -> float:
    """|burnt box centre − planned box centre| in the part's frame, mm."""
    r = render_placement(p, Variables(serial))
    plan = np.vstack(r.polylines(r.placed()))
    return float(np.linalg.norm(burnt_centre(world.burns, T_world_part)
                                - (plan.min(0) + plan.max(0)) / 2))


def run(args, folder: Path, field: Path, height) -> tuple[list, dict, dict]:
    """Both runs of produce; (records, truths by part, truth offsets by part)."""
    recipe_path = folder / "recipe.json"
    p = placement(args.module)
    part = make_workpiece(PART)                 # the part's mesh in its own frame
    write_mesh(folder / "part.stl", np.array(part.vertices), np.array(part.triangles))
    write_recipe(recipe_path, Recipe(folder / "part.stl", "mesh", (p,),
                                     scan=RecipeScan(margin_mm=4.0, spacing_mm=args.spacing,
                                                     cross=bool(args.cross),
                                                     cross_spacing_mm=args.cross,
                                                     second_look=args.second_look),
                                     serial_start=1,
                                     workpiece=PART))
    from insitu.cli.recipe import read

    recipe = read(recipe_path)
    log = folder / "run.jsonl"
    truths, offsets = {}, {}
    locate = recipe_locator(recipe, scan_camera(None, height))
    for attempt in ("first", "resumed"):
        with connect(None, PART, args.seed, args.binning, field=field) as station:
            present = station.part_feeder(PART, args.seed)
            cam = station.devices.camera

            def put(k, present=present):
                truths[k] = present(k)

            def stage(k, name, cam=cam, attempt=attempt):
                if attempt == "first" and k == args.fault_at and name == "scan":
                    cam.fail_after(20)

            def seen(rec, station=station):
                if rec.outcome == "marked":
                    offsets[rec.part] = truth_offset(station.world, truths[rec.part], p,
                                                     rec.serial)
                console.print(f"part {rec.part}: {rec.outcome}, serial {rec.serial}, "
                              f"{rec.error or ''}", highlight=False)

            job = production.Production(recipe, station, log, args.count, locate,
                                        read_part, put, height_cal=height,
                                        on_record=seen, on_stage=stage)
            try:
                production.produce(job, resume=attempt == "resumed")
            except DeviceError as e:
                console.print(f"run stopped as expected: {e}", highlight=False)
    return read_log(log), truths, offsets


def report(args) -> None:
    """Calibrate, run, resume and print both tables (``args``: count, binning, seed,
    fault_at, module, spacing, cross: the crossed pass's spacing or None, second_look)."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        field, height = calibrations(folder, args.seed, args.binning)
        t_cal = time.perf_counter() - t0
        records, truths, offsets = run(args, folder, field, height)
        t_run = time.perf_counter() - t0 - t_cal
        counter = folder / "serial.counter.json"
        issued = [i.serial for i in read_counter(counter).issued] if counter.exists() else []
    last = {r.part: r for r in records}
    tab = Table(title=f"produce: {args.count} parts of the {PART}, random poses (seed "
                      f"{args.seed}), binning {args.binning}, lines {args.spacing} mm apart"
                      + (f" and crossed {args.cross} mm apart" if args.cross else "") + ", "
                      f"QR {args.module} mm modules; "
                      f"camera fault at part {args.fault_at}, resumed")
    for c in ("part", "serial", "outcome", "pose truth (x, y, °)", "pose error mm / °",
              "on part vs recipe mm (truth)", "read back", "grade", "offset read mm",
              "scan/rescan/locate/plan/mark/read s"):
        tab.add_column(c)
    for r in records:
        tx, ty, ta = flat_pose(truths[r.part])
        err = "-"
        if r.x_mm is not None:
            da = (r.angle_deg - ta + 180) % 360 - 180
            err = f"{np.hypot(r.x_mm - tx, r.y_mm - ty):.3f} / {abs(da):.3f}"
        times = "/".join("-" if getattr(r, f"{s}_s") is None else f"{getattr(r, f'{s}_s'):.1f}"
                         for s in ("scan", "rescan", "locate", "plan", "mark", "read"))
        tab.add_row(str(r.part), str(r.serial), r.outcome + (" (resumed)" if r.resumed else ""),
                    f"{tx:.2f}, {ty:.2f}, {ta:.1f}", err,
                    f"{offsets[r.part]:.3f}" if r.outcome == "marked" else "-",
                    "-" if r.decoded is None
                    else f"{r.decoded} ({'=' if r.decode_ok else '≠'} plan)",
                    r.grade or "-", "-" if r.offset_mm is None else f"{r.offset_mm:.3f}", times)
    console.print(tab)
    marked = [r for r in last.values() if r.outcome == "marked"]
    serials = Counter(r.serial for r in records if r.serial is not None and r.outcome == "marked")
    s = Table(title="production: what must be true")
    for c in ("check", "measured", "required"):
        s.add_column(c)
    s.add_row("log complete: parts with a last record", f"{len(last)} of {args.count}",
              f"{args.count}")
    s.add_row("parts marked", f"{len(marked)}", f"{args.count}")
    looked = [r for r in last.values() if r.rescan_s is not None]
    s.add_row("second looks (scanned again crossed)", f"{len(looked)}, "
              f"{sum(r.outcome == 'marked' for r in looked)} of them marked", "")
    s.add_row("serials issued (counter)", f"{issued[:3]}…{issued[-2:]} ({len(issued)}, "
              f"distinct {len(set(issued))}; = 1 … {len(marked)}: "
              f"{issued == list(range(1, len(marked) + 1))})", f"1 … {len(marked)} once each")
    s.add_row("serials marked (log)", "1 … {} each once: {}".format(
        len(marked), sorted(serials) == list(range(1, len(marked) + 1))
        and set(serials.values()) == {1}), "yes")
    s.add_row("faulted part", "; ".join(f"part {r.part} {r.outcome}, serial {r.serial}"
                                        for r in records if r.outcome == "fault"), "no serial")
    off = np.array([offsets[r.part] for r in marked]) if marked else np.array([np.nan])
    s.add_row("code centre on the part vs recipe (truth)",
              f"max {off.max():.3f}, mean {off.mean():.3f} mm", "≤ 0.10 mm")
    rb = np.array([r.offset_mm for r in marked if r.offset_mm is not None] or [np.nan])
    s.add_row("code centre as read back vs plan", f"max {rb.max():.3f}, mean {rb.mean():.3f} mm",
              "≤ 0.10 mm")
    s.add_row("decoded = planned", f"{sum(bool(r.decode_ok) for r in marked)} of {len(marked)}",
              "all")
    s.add_row("grades", " ".join(f"{g}×{n}" for g, n in sorted(Counter(
        r.grade for r in marked).items(), key=lambda kv: str(kv[0]))), "reported")
    s.add_row("time", f"calibrations {t_cal:.0f} s; {len(records)} part records in {t_run:.0f} s "
                      f"({t_run / max(len(records), 1):.1f} s each)", "")
    console.print(s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument("--binning", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--fault-at", type=int, default=7)
    ap.add_argument("--module", type=float, default=0.35)
    ap.add_argument("--spacing", type=float, default=0.25, help="scan line spacing, mm")
    ap.add_argument("--cross", type=float, default=None, metavar="MM",
                    help="scan crossed: a second pass at 45° to x, its lines MM apart")
    ap.add_argument("--no-second-look", dest="second_look", action="store_false",
                    help="along y only: refuse a part whose pose the lines leave unheld "
                         "instead of scanning it again crossed")
    report(ap.parse_args())


if __name__ == "__main__":
    main()
