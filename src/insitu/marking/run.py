"""Executing a compiled job on a controller: the laser is off whenever anything raises, and
an interrupted job records how far it got so that it can resume from the next path.

Progress file (beside the job, ``<job>.progress.json``, written atomically after every path):
``{"format": "insitu-job-progress/1", "job_sha256": …, "paths_total": N, "completed": k,
"last_completed_path": k − 1 or null, "state": "running" | "interrupted" | "cancelled" |
"done", "error": …, "updated": ISO-8601 UTC}``. ``completed`` paths 0 … k − 1 are done;
resuming starts at path k (a path cut short is marked again from its start).
"""

from __future__ import annotations

import json
import threading
from contextlib import suppress
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from insitu.devices.galvo import Controller
from insitu.errors import DeviceError, FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.validation import read_json
from insitu.marking.driver import GalvoDriver
from insitu.marking.job import MarkJob

PROGRESS_FORMAT = "insitu-job-progress/1"


@dataclass(frozen=True)
class RunResult:
    """state: "done" | "cancelled"; paths [start_path, completed) were marked by this run."""

    state: str
    completed: int
    total: int
    start_path: int


def progress_path_for(job_path: str | Path) -> Path:
    """``parts/job.json`` → ``parts/job.progress.json``."""
    p = Path(job_path)
    return p.with_name(p.stem + ".progress.json")


def read_progress(path: str | Path) -> dict | None:
    """The progress record, or None when there is none."""
    path = Path(path)
    if not path.exists():
        return None
    d = read_json(path)
    if not isinstance(d, dict) or d.get("format") != PROGRESS_FORMAT or not isinstance(
            d.get("completed"), int):
        raise FormatError(f"{path}: not a job progress file ({PROGRESS_FORMAT})")
    return d


def _write(path: Path | None, job_sha: str, total: int, completed: int, state: str,
           error: str | None = None) -> None:
    if path is None:
        return
    rec = {"format": PROGRESS_FORMAT, "job_sha256": job_sha, "paths_total": total,
           "completed": completed, "last_completed_path": completed - 1 if completed else None,
           "state": state, "error": error,
           "updated": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}
    atomic_write_text(path, json.dumps(rec, indent=1) + "\n")


def resume_point(job: MarkJob, progress_path: str | Path) -> int:
    """The first path still to mark according to the progress file (0 without one).
    FormatError if the file records another job."""
    rec = read_progress(progress_path)
    if rec is None:
        return 0
    if rec.get("job_sha256") != job.digest():
        raise FormatError(f"{progress_path}: job_sha256: records another job; delete it to "
                          "start this job from the beginning")
    return min(max(rec["completed"], 0), len(job.paths))


def _safe_off(controller: Controller, primary: BaseException | None) -> None:
    try:
        controller.laser_off()
    except Exception as e:                          # noqa: BLE001 — a broken controller
        if primary is None:
            raise DeviceError(f"scan head: could not turn the laser off ({e})") from e


def run_job(job: MarkJob, driver: GalvoDriver, controller: Controller,
            progress_path: str | Path | None = None, resume: bool = False,
            cancel: threading.Event | None = None,
            progress: Callable[[int, int], None] | None = None) -> RunResult:
    """Mark ``job``: compile (SafetyError before any command), then send one path at a time.

    ``resume``: start after the last path the progress file records (a job already "done"
    sends nothing); otherwise start at path 0 and overwrite the record. ``cancel``: checked
    between paths. The controller's ``laser_off`` is called however this ends; on an
    exception the record says "interrupted" with the error, and the exception propagates.
    """
    ppath = Path(progress_path) if progress_path is not None else None
    start = resume_point(job, ppath) if (resume and ppath is not None) else 0
    total, sha = len(job.paths), job.digest()
    if start >= total and resume:
        _write(ppath, sha, total, total, "done")
        return RunResult("done", total, total, start)
    paths = driver.compile(job, first_path=start)
    done, err = start, None
    _write(ppath, sha, total, done, "running")
    try:
        for cmds in paths:
            if cancel is not None and cancel.is_set():
                _write(ppath, sha, total, done, "cancelled")
                return RunResult("cancelled", done, total, start)
            controller.execute(cmds)
            done += 1
            _write(ppath, sha, total, done, "running" if done < total else "done")
            if progress:
                progress(done, total)
        return RunResult("done", done, total, start)
    except BaseException as e:
        err = e
        try:
            with suppress(Exception):           # the original error matters more
                _write(ppath, sha, total, done, "interrupted", f"{type(e).__name__}: {e}")
        finally:
            _safe_off(controller, err)
        raise
    finally:
        if err is None:
            _safe_off(controller, None)


def run_preview(job: MarkJob, driver: GalvoDriver, controller: Controller,
                outline: str = "hull", speed_mm_s: float = 1000.0, repeat: int = 1) -> None:
    """Draw the job's outline with the pilot laser (see :meth:`GalvoDriver.preview`); the
    laser is off when this returns or raises."""
    cmds = driver.preview(job, outline, speed_mm_s, repeat)
    err = None
    try:
        controller.execute(cmds)
    except BaseException as e:
        err = e
        raise
    finally:
        _safe_off(controller, err)
