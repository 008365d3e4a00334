"""`produce` on the step block with a QR code, one line a frame against several lines per
exposure (issue 32): the station seconds and the processing CPU seconds of each step per
part, from the production log's ``<step>_station_s`` and ``<step>_cpu_s`` (the station clock
of the simulated devices, :mod:`insitu.sim.clock`; the CPU of this process less the
simulator's drawing), the processing held to one core (BLAS and OpenCV one thread; run under
``taskset -c 0`` for the whole process).

Data: insitu's simulator (rig seed 11), the step block at random poses (seed 1), binning 2,
Method 2 with ``tests/data/height-cal-b2.json`` (no crossed sheet: no second look), no field
correction (timing only: where the code lands is benchmarks/production_run.py's), lines
0.5 mm apart swept at 10 m/s (the simulated head's own speed; the recipe's default is
2 m/s), the QR 0.35 mm modules on the 3 mm step.

Run: nice taskset -c 0 .venv/bin/python benchmarks/produce_clock.py [--parts 3]
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
from insitu.marking import Placement  # noqa: E402
from insitu.services import production  # noqa: E402
from insitu.services.height import scan_camera  # noqa: E402
from insitu.services.locate import recipe_locator  # noqa: E402
from insitu.services.station import connect  # noqa: E402
from insitu.sim.workpieces import make_workpiece  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PART, STEPS = "step-block", ("scan", "locate", "plan", "mark", "read")
RIG_SEED = 11               # the rig tests/data/height-cal-b2.json was recorded on


def run(folder: Path, per_frame, parts: int, seed: int, binning: int) -> list:
    """One produce run of ``parts`` parts with ``per_frame`` lines a frame: its log."""
    height = load_json_model(ROOT / "tests/data/height-cal-b2.json", HeightCalibration)
    part = make_workpiece(PART)
    write_mesh(folder / "part.stl", np.array(part.vertices), np.array(part.triangles))
    p = Placement('qr:"{serial:05d}";ec=M', (0.0, -30.0), 21 * 0.35, 20.0)
    recipe_path = folder / "recipe.json"
    write_recipe(recipe_path, Recipe(folder / "part.stl", "mesh", (p,), serial_start=1,
                                     scan=RecipeScan(margin_mm=4.0, spacing_mm=0.5,
                                                     speed_mm_s=10000.0,
                                                     lines_per_frame=per_frame),
                                     workpiece=PART))
    from insitu.cli.recipe import read

    recipe = read(recipe_path)
    locate = recipe_locator(recipe, scan_camera(None, height))
    with connect(None, PART, RIG_SEED, binning) as station:
        present = station.part_feeder(PART, seed)
        job = production.Production(recipe, station, folder / "run.jsonl", parts, locate,
                                    production.read_part, present, height_cal=height)
        production.produce(job)
    return read_log(folder / "run.jsonl")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--binning", type=int, default=2)
    args = ap.parse_args()
    cv2.setNumThreads(1)
    t = Table(title=f"produce, {PART} + QR, binning {args.binning}, lines 0.5 mm apart: "
                    "station s / processing CPU s (one core) per step, mean of the marked "
                    "parts")
    for col in ("lines a frame", "parts marked", *STEPS, "part: station s", "part: CPU s",
                "CPU / station"):
        t.add_column(col)
    for per_frame in (None, "auto"):
        with tempfile.TemporaryDirectory() as tmp:
            log = run(Path(tmp), per_frame, args.parts, args.seed, args.binning)
        done = [r for r in log if r.outcome == "marked"] or log
        cells, st_total, cpu_total = [], 0.0, 0.0
        for s in STEPS:
            st = np.mean([getattr(r, f"{s}_station_s") or 0.0 for r in done])
            cpu = np.mean([getattr(r, f"{s}_cpu_s") or 0.0 for r in done])
            cells.append(f"{st:.2f} / {cpu:.2f}")
            st_total, cpu_total = st_total + st, cpu_total + cpu
        t.add_row(str(per_frame or 1), f"{sum(r.outcome == 'marked' for r in log)} of "
                  f"{len(log)}", *cells, f"{st_total:.2f}", f"{cpu_total:.2f}",
                  f"{cpu_total / st_total:.2f}")
        print(per_frame, [(r.part, r.outcome, r.error) for r in log], flush=True)
    Console(width=170).print(t)


if __name__ == "__main__":
    main()
