"""``insitu job``: show or run a mark job file (docs/formats.md, mark job) on the rig."""

from __future__ import annotations

import contextlib
import signal
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table
from rich.text import Text

from insitu.cli.common import check_output, console, one_line_errors, progress_bar, warn
from insitu.cli.options import (
    CutPath,
    Field,
    Inspect,
    PartPose,
    Preview,
    Restart,
    Resume,
    Rig,
    Seed,
    Workpiece,
)
from insitu.errors import InsituError

app = typer.Typer(help="Mark jobs: show one, or mark it on the rig.", no_args_is_help=True,
                  rich_markup_mode="markdown")

class Stopped(InsituError):
    """A signal (SIGTERM, SIGHUP) stopped the marking."""


@contextlib.contextmanager
def on_signals(handler):
    """``handler(signum, frame)`` for SIGTERM and SIGHUP inside the block; the old ones after."""
    old = {sig: signal.signal(sig, handler) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


@contextlib.contextmanager
def stop_on_signals(what: str = "marking", hint: str = " (insitu job show JOB.json says how "
                                                       "far it got)"):
    """SIGTERM and SIGHUP end ``what`` as Ctrl-C does: :class:`Stopped` is raised where the
    program is, so the laser goes off and the journal records "interrupted"; further signals
    are ignored while that happens."""
    def stop(signum, _frame):
        for sig in (signal.SIGTERM, signal.SIGHUP):
            signal.signal(sig, signal.SIG_IGN)
        raise Stopped(f"{what} stopped by {signal.Signals(signum).name}; the laser is off"
                      + hint)

    with on_signals(stop):
        yield


def check_run_options(resume: bool, restart: bool, cut_path: str | None) -> None:
    """One line for options of a marking run that do not go together."""
    from insitu.marking import CUT_CHOICES

    if cut_path is not None and cut_path not in CUT_CHOICES:
        raise InsituError(f"--cut-path {cut_path!r}: expected one of {', '.join(CUT_CHOICES)}")
    if cut_path is not None and not resume:
        raise InsituError("--cut-path goes with --resume")
    if resume and restart:
        raise InsituError("--resume and --restart: choose one")


def run_on_station(station, job, job_path: Path, resume: bool, preview: bool,
                   inspect: Path | None, restart: bool = False,
                   cut_path: str | None = None, read=None) -> None:
    """:func:`insitu.services.mark.mark_on_station` with a progress bar (SIGTERM and SIGHUP
    stop it like Ctrl-C), then say how far it got and where the camera's image went. With
    ``read`` = (plans, cloud), ``inspect`` gets the marks read back
    (:mod:`insitu.services.inspect`: the rectified picture with the plan, the raw frame
    beside it) and their table is printed; else the raw frame."""
    from insitu.marking import journal_path_for
    from insitu.services.mark import mark_on_station

    with stop_on_signals(), progress_bar("marking", "paths") as progress:
        run = mark_on_station(station, job, job_path, resume=resume, restart=restart,
                              cut_path=cut_path, preview=preview,
                              inspect=inspect if read is None else None,
                              image=read is not None and inspect is not None,
                              progress=progress)
    r = run.result
    done = (f"marked paths {r.start_path + 1}…{r.completed} of {r.total}"
            if r.start_path < r.total else
            f"nothing left to mark: {r.completed} of {r.total} paths were marked")
    cut = f", cut path {r.cut + 1}: {r.cut_choice}" if r.cut is not None else ""
    console.print(f"{done} ({r.state}{cut}); journal in {journal_path_for(job_path)}",
                  highlight=False)
    console.print(step_time_text("marking", run.time), highlight=False)
    if inspect is not None and read is not None:
        from insitu.services.inspect import read_back, save_read_back

        with progress_bar("reading back", "marks") as progress:
            progress(0, 1)
            result = read_back(station, read[0], read[1], image=run.image)
        raw = save_read_back(inspect, result)
        print_read_back(result)
        console.print(f"wrote {inspect} (the raw frame: {raw})", highlight=False)
    elif inspect is not None:
        console.print(f"wrote {inspect}", highlight=False)


def step_time_text(what: str, t) -> str:
    """``what``'s seconds in one line: the station's own (its devices'; a real rig has only
    the wall clock), the computer's processing CPU and the wall clock's."""
    station = (f"station {t.station:.2f} s" if t.station is not None
               else "station: a real rig (its time is the wall clock's)")
    return f"{what}: {station}, CPU {t.cpu:.2f} s, wall {t.wall:.1f} s"


def print_read_back(result) -> None:
    """The read-back table: per mark, decoded, = plan?, offset, grade."""
    from insitu.services.inspect import table_rows

    table = Table(title="read back by the camera")
    for head in ("mark", "planned", "decoded", "= plan", "offset u, v mm", "seen", "grade"):
        table.add_column(head)
    for row in table_rows(result):
        table.add_row(*(Text(c) for c in row))
    console.print(table)


@app.command("show")
@one_line_errors
def show(job_path: Annotated[Path, typer.Argument(metavar="JOB.json", help="Mark job.")]) -> None:
    """What a job holds: paths, extent, heights, laser, estimated time, and how far an earlier
    run got."""
    from insitu.marking import estimate_time, history, progress_path_for, read_job

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
    for name, idx in job.pens().items():
        if name:
            table.add_row(f"pen {name}", f"{len(idx):,} path{'s' * (len(idx) != 1)}: "
                                         f"{pen_text(job, idx[0])}")
    table.add_row("estimated time", f"{e.total_s:.1f} s (mark {e.mark_mm:.0f} mm, jump "
                                    f"{e.jump_mm:.0f} mm)")
    s = history(job, progress_path_for(job_path))
    if s is not None:
        table.add_row("last run", f"{s.state}: {len(s.done)} of {s.paths_total} paths done"
                                  + (f", {len(s.skipped)} skipped" if s.skipped else "")
                                  + f" ({s.updated}; {s.runs} run{'s' * (s.runs != 1)})")
        if s.error:
            table.add_row("error", s.error)
        if s.cut is not None:
            pos = ("the board reported no position" if s.cut_position is None else
                   f"{s.cut_position} of {job.path_passes(s.cut) * max(len(job.paths[s.cut].points) - 1, 1)}"
                   " marks done")
            table.add_row("cut path", f"{s.cut + 1} ({pos}): --resume --cut-path "
                                      "remark|skip|continue")
    _variable_rows(table, job, job_path)
    console.print(table)


def pen_text(job, i: int) -> str:
    """Path ``i``'s laser as its pen gives it: ``80 %, 20 kHz, 200 mm/s, jump 3000 mm/s,
    2 passes, delays 100/150/250/150/100 µs, wobble 0.1 mm 500 Hz``."""
    las, t, w = job.path_laser(i), job.path_timing(i), job.path_wobble(i)
    n = job.path_passes(i)
    text = (f"{las.power_pct:g} %, {las.frequency_khz:g} kHz, {las.mark_speed_mm_s:g} mm/s, "
            f"jump {las.jump_speed_mm_s:g} mm/s, {n} pass{'es' * (n != 1)}, delays "
            f"{t.laser_on_delay_us:g}/{t.laser_off_delay_us:g}/{t.jump_delay_us:g}/"
            f"{t.mark_delay_us:g}/{t.polygon_delay_us:g} µs (on/off/jump/mark/polygon)")
    if w is not None:
        text += f", wobble {w.amplitude_mm:g} mm {w.hz(las.mark_speed_mm_s):g} Hz"
    return text


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
    resume: Resume = False, restart: Restart = False, cut_path: CutPath = None,
    preview: Preview = False, inspect: Inspect = None, rig: Rig = None,
    field: Field = None, workpiece: Workpiece = "step-block", seed: Seed = 0,
    pose: PartPose = (0.0, 0.0, 0.0),
) -> None:
    """Mark a job file on the rig. Every target is checked against the scan field, the focus
    range (after the field correction) and the board's limits before the first command; the
    laser is on only while marking and off at once on any fault or SIGINT/SIGTERM/SIGHUP. The
    journal beside the job records each path started and done: an interrupted job is not run
    again without --resume (the paths not done; a path cut short as --cut-path says) or
    --restart."""
    from insitu.marking import read_job
    from insitu.services.station import connect

    check_run_options(resume, restart, cut_path)
    if inspect is not None:
        check_output(inspect, ".png")
    job = read_job(job_path)
    with connect(rig, workpiece, seed, field=field, pose=pose) as station:
        if warning := station.check_source(job_path, job.rig, "job"):
            warn(warning)
        run_on_station(station, job, job_path, resume, preview, inspect, restart, cut_path)
