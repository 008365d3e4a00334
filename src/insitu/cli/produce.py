"""``insitu produce``: mark a recipe on part after part, each located where it lies."""

from __future__ import annotations

import sys
import threading
from pathlib import Path
from typing import Annotated

import typer
from rich.text import Text

from insitu.cli.common import bounded, check_output, console, fail, one_line_errors, progress_bar
from insitu.cli.job import on_signals
from insitu.cli.options import Field, Rig, Seed, rig_height_calibration
from insitu.errors import InsituError
from insitu.formats.production_log import STAGES
from insitu.formats.project import SIM_BINNING
from insitu.services.scan import Cancelled


class EnterKey:
    """The operator starts each part with Enter (``q`` then Enter, or end of input, stops)."""

    def wait(self, part: int, cancel: threading.Event) -> None:
        console.print(f"part {part}: put the part on the table, Enter to start (q: stop)",
                      highlight=False)
        line = sys.stdin.readline()
        if cancel.is_set() or not line or line.strip().lower() == "q":
            raise Cancelled(f"production stopped by the operator before part {part}")


def cancel_on_signals(cancel: threading.Event):
    """SIGTERM and SIGHUP set ``cancel``: the marking stops at once (laser off), the part is
    logged as aborted, and the run ends."""
    return on_signals(lambda _signum, _frame: cancel.set())


def part_line(rec) -> Text:
    """One line per part: outcome, serial, pose, fit, read-back, time."""
    style = {"marked": "yellow" if rec.error else "green",
             "refused": "yellow"}.get(rec.outcome, "bold red")
    bits = [f"serial {rec.serial}" if rec.serial is not None else "no serial"]
    if rec.x_mm is not None:
        bits.append(f"at ({rec.x_mm:.2f}, {rec.y_mm:.2f}) mm, {rec.angle_deg:.2f}°, fitness "
                    f"{rec.fitness:.3f}")
    if rec.decoded is not None or rec.grade is not None:
        bits.append(f"read {rec.decoded!r} ({'ok' if rec.decode_ok else 'NOT the plan'}), "
                    f"grade {rec.grade}, offset {rec.offset_mm} mm")
    if rec.rescan_s is not None:
        bits.append(f"second look, crossed ({rec.rescan_s:.1f} s)")
    total = sum(getattr(rec, f"{s}_s") or 0.0 for s in STAGES)
    station = [getattr(rec, f"{s}_station_s") for s in STAGES]
    cpu = sum(getattr(rec, f"{s}_cpu_s") or 0.0 for s in STAGES)
    if any(v is not None for v in station):
        bits.append(f"station {sum(v or 0.0 for v in station):.2f} s, CPU {cpu:.2f} s, "
                    f"wall {total:.1f} s")
    else:
        bits.append(f"CPU {cpu:.2f} s, wall {total:.1f} s")
    if rec.error:
        bits.append(rec.error)
    return Text.assemble((f"part {rec.part} {rec.outcome}", style), ": " + "; ".join(bits))


RecipeFile = Annotated[Path, typer.Argument(metavar="RECIPE.json",
                                            help="Production recipe (insitu recipe new).")]
Count = Annotated[int, typer.Option(callback=bounded("parts"),
                                    help="Parts in the run (numbered 1 … N).")]
RandomPoses = Annotated[int | None, typer.Option(
    metavar="SEED", callback=bounded("seed"),
    help="Simulated rig: each part on the table at a random pose (±25 mm, any turn), drawn "
         "from SEED and its number.")]
ResumeRun = Annotated[bool, typer.Option(
    help="Continue the run of the log: finish the interrupted part with its own serial (its "
         "job's journal says what is marked again), then the next parts.")]
Log = Annotated[Path | None, typer.Option(
    help="The run's log (.jsonl; a .csv is written beside it, and each part's job and cloud in "
         "its folder). Default: RECIPE's name + .production.jsonl.")]
Wait = Annotated[bool | None, typer.Option(
    "--wait/--no-wait", help="Wait for Enter before each part (default: on a real rig; the "
                             "simulated rig puts each part on by itself).")]
HeightCal = Annotated[Path | None, typer.Option(
    "--height-cal", help="Height calibration of the scans (default: the rig file's; none: "
                         "Method 1).")]
Binning = Annotated[int, typer.Option(callback=bounded("binning"),
                                      help="Simulated rig: divide the image size by this.")]


@one_line_errors
def produce(recipe: RecipeFile, rig: Rig = None, field: Field = None, count: Count = 1,
            random_poses: RandomPoses = None, resume: ResumeRun = False, log: Log = None,
            wait: Wait = None, height_cal: HeightCal = None, seed: Seed = 0,
            binning: Binning = SIM_BINNING) -> None:
    """For each part: wait for the start (Enter, or at once), scan the region, locate the part,
    move the recipe's placements where it lies, check and mark them as one job, read the mark
    back, and log one line (LOG.jsonl and LOG.csv). A part not found or refused by the checks
    takes no serial and is set aside; a device fault or an abort (Ctrl+C, SIGTERM) turns the
    laser off, logs the part with its serial and ends the run: --resume finishes that part
    with the same serial and goes on. Serials are never reused or skipped."""
    from insitu import services
    from insitu.cli.recipe import read
    from insitu.formats.production_log import read_log
    from insitu.services import production
    from insitu.services.height import scan_camera
    from insitu.services.locate import recipe_locator
    from insitu.services.part_reading import read_part
    from insitu.services.station import connect

    r = read(recipe)
    log = log if log is not None else recipe.with_name(recipe.name.removesuffix(".json")
                                                       + ".production.jsonl")
    check_output(log, ".jsonl")
    if height_cal is None and rig is not None:
        height_cal = rig_height_calibration(rig)
    cal = services.load_height_calibration(height_cal) if height_cal is not None else None
    cancel = threading.Event()
    with connect(rig, r.workpiece or "step-block", seed, binning, field=field) as station:
        present = station.part_feeder(r.workpiece or "step-block", random_poses)
        if random_poses is not None and present is None:
            fail("--random-poses: only the simulated rig puts parts on the table")
        start = (EnterKey() if (wait if wait is not None else station.world is None)
                 else production.NoWait())
        with progress_bar("producing", "parts") as progress:
            def on_record(rec) -> None:
                console.print(part_line(rec), highlight=False)
                progress(rec.part, count)

            locate = recipe_locator(r, scan_camera(station.rig.camera, cal))
            run = production.Production(r, station, log, count, locate,
                                        read_part, present, start, cancel,
                                        cal, on_record)
            before = len(read_log(log))
            try:
                with cancel_on_signals(cancel):
                    records = production.produce(run, resume)
            except InsituError as e:
                if len(read_log(log)) == before:      # refused before any part
                    raise
                fail(f"{e}; the laser is off; logged in {log}: --resume continues the run")
    marked = sum(rec.outcome == "marked" for rec in records)
    console.print(f"{marked} of {len(records)} parts marked; log {log} and "
                  f"{log.with_suffix('.csv')}", highlight=False)
