"""`produce` on the step block with a QR code, one line a frame against several lines per
exposure (issue 32): the station seconds and the processing CPU seconds of each step per
part, from the production log's ``<step>_station_s`` and ``<step>_cpu_s`` (the station clock
of the simulated devices, :mod:`insitu.sim.clock`; the CPU of this process less the
simulator's drawing), the processing held to one core (BLAS and OpenCV one thread; run under
``taskset -c 0`` for the whole process).

Data: insitu's simulator (rig seed 11), the step block at random poses (seed 1), binning 2,
Method 2 with ``tests/data/height-cal-b2.json`` (no crossed sheet: no second look), no field
correction, the part's footprint + 4 mm scanned with lines ``--spacing`` apart swept at
10 m/s (the simulated head's fastest; the recipe's default is 2 m/s), the QR 0.35 mm modules
on the 3 mm step. Beside the times: the code's read-back (decoded, grade, the marks' largest
offset from their planned place, mm; where the code lands to the truth is
benchmarks/production_run.py's) and the marking's own estimate split into marks, the pens'
delays and jumps. Without a field correction that offset is the head's field distortion where
the code lies plus the rig frame's constant shift (seed 8: 0.30 mm at world (−46, 12.5), as
the simulator's burns say); produce logs a part beyond the recipe's
``read.offset_tolerance_mm`` (0.1 mm) with that reason.

``--survey 4``: the recipe's ``scan.survey_mm``, a first pass of lines 4 mm apart bounds the
part (:mod:`insitu.services.survey`), the dense lines sweep its outline only. The located
pose against the truth the feeder put the part at (the worst of the parts, mm and degrees)
checks that the clipped scan locates as well. Pose seeds: 1 tuned on; 2 spent; 3–8 held out
(fixed before the survey's results were seen), each run once and spent.

Run: nice taskset -c 0 .venv/bin/python benchmarks/produce_clock.py [--parts 3]
[--seed 1] [--spacing 0.5,0.7] [--per-frame 1,auto] [--survey none,4]
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from insitu.formats.calibration import HeightCalibration  # noqa: E402
from insitu.formats.json_file import load_json_model  # noqa: E402
from insitu.formats.mesh import write_mesh  # noqa: E402
from insitu.formats.production_log import read_log  # noqa: E402
from insitu.formats.recipe import Recipe, RecipeScan, write_recipe  # noqa: E402
from insitu.geometry.pose import flat_pose  # noqa: E402
from insitu.marking import Placement, estimate_time, read_job  # noqa: E402
from insitu.services import production  # noqa: E402
from insitu.services.height import scan_camera  # noqa: E402
from insitu.services.locate import recipe_locator  # noqa: E402
from insitu.services.part_reading import read_part  # noqa: E402
from insitu.services.station import connect  # noqa: E402
from insitu.sim.workpieces import make_workpiece  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PART, STEPS = "step-block", ("scan", "locate", "plan", "mark", "read")
RIG_SEED = 11               # the rig tests/data/height-cal-b2.json was recorded on


def run(folder: Path, per_frame, parts: int, seed: int, binning: int,
        spacing: float = 0.5, survey: float | None = None) -> tuple[list, list]:
    """One produce run of ``parts`` parts with ``per_frame`` lines a frame, lines
    ``spacing`` mm apart (``survey``: the part first found by lines this far apart,
    the recipe's ``scan.survey_mm``): its
    log and each marked part's marking estimate."""
    height = load_json_model(ROOT / "tests/data/height-cal-b2.json", HeightCalibration)
    part = make_workpiece(PART)
    write_mesh(folder / "part.stl", np.array(part.vertices), np.array(part.triangles))
    p = Placement('qr:"{serial:05d}";ec=M', (0.0, -30.0), 21 * 0.35, 20.0)
    recipe_path = folder / "recipe.json"
    write_recipe(recipe_path, Recipe(folder / "part.stl", "mesh", (p,), serial_start=1,
                                     scan=RecipeScan(margin_mm=4.0, spacing_mm=spacing,
                                                     speed_mm_s=10000.0,
                                                     lines_per_frame=per_frame,
                                                     survey_mm=survey),
                                     workpiece=PART))
    from insitu.cli.recipe import read

    recipe = read(recipe_path)
    locate = recipe_locator(recipe, scan_camera(None, height))
    with connect(None, PART, RIG_SEED, binning) as station:
        feeder, truths = station.part_feeder(PART, seed), {}

        def present(k: int):
            T = feeder(k)
            truths[k] = flat_pose(T)
            return T

        job = production.Production(recipe, station, folder / "run.jsonl", parts, locate,
                                    read_part, present, height_cal=height)
        production.produce(job)
    log = read_log(folder / "run.jsonl")
    jobs = [folder / f"part-{r.part:04d}.job.json" for r in log if r.outcome == "marked"]
    errors = [located_error(r, truths[r.part]) for r in log if r.x_mm is not None]
    return log, [estimate_time(read_job(j)) for j in jobs if j.exists()], errors


def located_error(r, truth) -> tuple[float, float]:
    """(mm, °) between the logged pose of part record ``r`` and its ``truth`` (x, y, °)."""
    tx, ty, ta = truth
    da = (r.angle_deg - ta + 180.0) % 360.0 - 180.0
    return float(np.hypot(r.x_mm - tx, r.y_mm - ty)), abs(float(da))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--binning", type=int, default=2)
    ap.add_argument("--spacing", default="0.5,0.7", help="line spacings, mm")
    ap.add_argument("--per-frame", default="1", help="lines a frame: 1, auto, K (comma list)")
    ap.add_argument("--survey", default="none", help="first passes' spacings, mm, or none "
                    "(the whole region; comma list)")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    t = Table(title=f"produce, {PART} + QR, binning {args.binning}: station s / processing "
                    "CPU s (one core) per step, mean of the marked parts")
    for col in ("lines", "marked", *STEPS, "part: station s", "part: CPU s", "CPU / station",
                "read back", "mark: marks / delays / jumps s", "located: worst mm / °"):
        t.add_column(col)
    runs = [(float(v), f, None if s == "none" else float(s)) for v in args.spacing.split(",")
            for f in args.per_frame.split(",") for s in args.survey.split(",")]
    for spacing, per_frame, survey in runs:
        k = None if per_frame == "1" else per_frame if per_frame == "auto" else int(per_frame)
        with tempfile.TemporaryDirectory() as tmp:
            log, est, err = run(Path(tmp), k, args.parts, args.seed, args.binning, spacing,
                                survey)
        t.add_row(*row(log, est, spacing, per_frame, survey, err))
        print(spacing, per_frame, survey, [(r.part, r.outcome, r.error) for r in log],
              [f"{e[0]:.4f} mm {e[1]:.4f}°" for e in err], flush=True)
    Console(width=190).print(t)


def row(log, est, spacing: float, per_frame: str, survey: float | None,
        err: list[tuple[float, float]]) -> list[str]:
    """The table's row of one run."""
    done = [r for r in log if r.outcome == "marked"] or log
    cells, st_total, cpu_total = [], 0.0, 0.0
    for s in STEPS:
        st = np.mean([getattr(r, f"{s}_station_s") or 0.0 for r in done])
        cpu = np.mean([getattr(r, f"{s}_cpu_s") or 0.0 for r in done])
        cells.append(f"{st:.2f} / {cpu:.2f}")
        st_total, cpu_total = st_total + st, cpu_total + cpu
    grades = "".join(sorted(r.grade or "-" for r in done))
    worst = max((r.offset_mm or 0.0 for r in done), default=0.0)
    read = f"{sum(bool(r.decoded) for r in done)} decoded, {grades}, ≤ {worst:.3f} mm"
    split = (" / ".join(f"{np.mean([getattr(e, k) for e in est]):.2f}"
                        for k in ("mark_s", "delay_s", "jump_s")) if est else "-")
    where = "the region" if survey is None else f"found by {survey:g} mm lines"
    return [f"{spacing:g} mm, {per_frame} a frame, {where}",
            f"{sum(r.outcome == 'marked' for r in log)} of {len(log)}", *cells,
            f"{st_total:.2f}", f"{cpu_total:.2f}", f"{cpu_total / st_total:.2f}", read, split,
            " / ".join(f"{max((e[i] for e in err), default=np.nan):.3f}" for i in (0, 1))]


if __name__ == "__main__":
    main()
