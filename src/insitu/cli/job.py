"""``insitu job``: show or run a mark job file (formats.md §3) on the rig."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from insitu.cli.common import bounded, check_output, console, one_line_errors, progress_bar

app = typer.Typer(help="Mark jobs: show one, or mark it on the rig.", no_args_is_help=True,
                  rich_markup_mode="markdown")

# options of every command that marks on the rig (``insitu job run``, ``insitu mark --run``)
Resume = Annotated[bool, typer.Option(help="Continue an interrupted job after its last "
                                           "completed path.")]
Preview = Annotated[bool, typer.Option(help="First draw the outline with the pilot laser.")]
Inspect = Annotated[Path | None, typer.Option(help="Write the camera's image of the marked "
                                                   "part (.png).")]
Rig = Annotated[Path | None, typer.Option(help="Rig file (default: the simulated rig).")]
Field = Annotated[Path | None, typer.Option(help="Field correction (FIELD.json) to apply "
                                                 "(default: the rig file's).")]
Workpiece = Annotated[str, typer.Option(help="Simulated rig: the part on the table.")]
Seed = Annotated[int, typer.Option(help="Simulated rig: seed.", callback=bounded("seed"))]


def run_on_station(station, job, job_path: Path, resume: bool, preview: bool,
                   inspect: Path | None) -> None:
    """:func:`insitu.services.mark.mark_on_station` with a progress bar, then say how far it
    got and where the camera's image of the result went."""
    from insitu.services.mark import mark_on_station

    with progress_bar("marking") as progress:
        run = mark_on_station(station, job, job_path, resume=resume, preview=preview,
                              inspect=inspect, progress=progress)
    r = run.result
    done = (f"marked paths {r.start_path + 1}…{r.completed} of {r.total}"
            if r.completed > r.start_path else
            f"nothing left to mark: {r.completed} of {r.total} paths were marked")
    console.print(f"{done} ({r.state}); progress in {run.progress_path}", highlight=False)
    if inspect is not None:
        console.print(f"wrote {inspect}", highlight=False)


@app.command("show")
@one_line_errors
def show(job_path: Annotated[Path, typer.Argument(metavar="JOB.json", help="Mark job.")]) -> None:
    """What a job holds: paths, extent, heights, laser, estimated time, and how far an earlier
    run got."""
    from insitu.marking import estimate_time, read_job, read_progress
    from insitu.services.mark import progress_path_for

    job = read_job(job_path)
    pts = np.vstack([p.points for p in job.paths])
    lo, hi = pts.min(0), pts.max(0)
    e = estimate_time(job)
    table = Table(title=str(job_path), show_header=False)
    table.add_row("paths", f"{len(job.paths):,} ({len(pts):,} points)")
    for axis, i in (("x", 0), ("y", 1), ("z", 2)):
        table.add_row(f"{axis} range, mm", f"{lo[i]:.3f} … {hi[i]:.3f}")
    las = job.laser
    table.add_row("laser", f"{las.power_pct:g} %, {las.frequency_khz:g} kHz, mark "
                           f"{las.mark_speed_mm_s:g} mm/s, jump {las.jump_speed_mm_s:g} mm/s")
    table.add_row("estimated time", f"{e.total_s:.1f} s (mark {e.mark_mm:.0f} mm, jump "
                                    f"{e.jump_mm:.0f} mm)")
    rec = read_progress(progress_path_for(job_path))
    if rec is not None:
        table.add_row("last run", f"{rec['state']}: {rec['completed']} of {rec['paths_total']} "
                                  f"paths ({rec['updated']})")
    _variable_rows(table, job, job_path)
    console.print(table)


def _variable_rows(table: Table, job, job_path: Path) -> None:
    """The job's serial, rendered texts and the counter's next serial (variable data)."""
    
    from insitu.services.serials import counter_next, job_variables

    var = job_variables(job, job_path)
    if var is None:
        return
    if var.serial is not None:
        path = var.counter_path(job_path)
        nxt = counter_next(path)
        table.add_row("serial", f"{var.serial}; counter {path}: next "
                                + (f"{nxt}" if nxt is not None else "(counter not found)"))
    for t in var.texts:
        table.add_row("text", f"{t.text}  ← {t.spec}")
    table.add_row("planned", var.time + "".join(f", {k}={v}"
                                                for k, v in var.fields.items()))


@app.command("run")
@one_line_errors
def run(
    job_path: Annotated[Path, typer.Argument(metavar="JOB.json", help="Mark job.")],
    resume: Resume = False, preview: Preview = False, inspect: Inspect = None, rig: Rig = None,
    field: Field = None, workpiece: Workpiece = "step-block", seed: Seed = 0,
) -> None:
    """Mark a job file on the rig. Every target is checked against the scan field and the focus
    range (after the field correction) before the first command; the laser is on only while
    marking and off at once on any fault; the progress file beside the job records the last
    completed path, so --resume continues an interrupted job."""
    from insitu.marking import read_job
    from insitu.services.station import connect

    if inspect is not None:
        check_output(inspect, ".png")
    job = read_job(job_path)
    with connect(rig, workpiece, seed, field=field) as station:
        run_on_station(station, job, job_path, resume, preview, inspect)
