"""What the operator confirms before the laser fires: the job's patterns, paths, marked
length, extent, time on the board, laser settings, the rig and workpiece, where the job and
its journal are kept — as (label, value) rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from insitu.marking import MarkJob, journal_path_for
from insitu.services.mark import BoardTime, board_seconds


def rig_text(record: dict | None) -> str:
    """A job's or cloud's rig record in words."""
    if not record:
        return "not recorded"
    if record.get("rig_file"):
        return f"rig file {record['rig_file']}"
    return (f"simulated, workpiece {record.get('workpiece', '?')}, seed {record.get('seed', 0)}"
            f", binning {record.get('binning', '?')}")


def arm_rows(job: MarkJob, patterns: list[str], station_text: str,
             time: BoardTime | None = None, first_path: int = 0, job_path: Path | None = None,
             choice: dict | None = None, unsaved: bool = False) -> list[tuple[str, str]]:
    """The rows of the arming summary of ``job`` (from ``first_path`` on when resuming):
    ``patterns`` placed (names), ``station_text`` (the station connected), ``time`` on the
    board (default: the plan's), ``choice``: the keywords of the run (resume, cut path,
    restart); ``unsaved``: ``job_path`` is in the working folder of a project never saved."""
    pts = np.vstack([p.points for p in job.paths])
    lo, hi = pts.min(0), pts.max(0)
    e = time or board_seconds(job, None, first_path)
    n = len(job.paths)
    las = job.laser
    own = sum(p.laser is not None for p in job.paths)
    rows = [("patterns", ", ".join(patterns) if patterns else "from the job file"),
            ("paths", f"{n - first_path} of {n}" if first_path else f"{n}"),
            ("marked length", f"{e.mark_mm:.0f} mm (jumps {e.jump_mm:.0f} mm)"),
            ("extent, mm", f"x {lo[0]:.2f} … {hi[0]:.2f}, y {lo[1]:.2f} … {hi[1]:.2f}, "
                           f"z {lo[2]:.2f} … {hi[2]:.2f}"),
            ("time", e.words()),
            ("laser", f"{las.power_pct:g} %, {las.frequency_khz:g} kHz, mark "
                      f"{las.mark_speed_mm_s:g} mm/s, jump {las.jump_speed_mm_s:g} mm/s"
                      + (f"; {own} paths with their own settings" if own else ""))]
    rows += [("planned on", rig_text(job.rig)), ("station", station_text)]
    if choice:
        how = ("again from the first path" if choice.get("restart") else
               "resume" + (f", cut path: {choice['cut_path']}" if choice.get("cut_path")
                           else ""))
        rows.append(("run", how))
    if job_path is not None:
        rows.append(("job file", str(job_path)))
        rows.append(("journal", str(journal_path_for(job_path)) + (
            " (the working folder of a project never saved)" if unsaved else "")))
    return rows
