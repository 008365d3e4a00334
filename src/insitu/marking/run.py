"""Executing a compiled job on a controller: every list is checked against the device before
the first is sent; the laser is off whenever anything raises; the journal beside the job
(:mod:`insitu.marking.journal`) records each path started and done, so that a resume never
marks a done path again and a path cut short is shown, to be marked again, skipped or
continued from where the board stopped.

Lists: path k is sent as ``compile(job, first_path=f)[k − f]`` of the run's ``first`` path f;
a continued path as :func:`resume_list` of its fresh list (``first`` = k) without its first
``skip_marks`` marks. Both are recorded in the ``started`` line, so that the list can be made
again to read a board's position after a restart. The progress record
(``<job>.progress.json``, :func:`~insitu.marking.journal.write_progress`) is written when a run
begins and ends, and every ``PROGRESS_EVERY_S`` in between (an atomic rewrite per path would
cost more than the journal's appends); the journal is the truth for resume.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from insitu.devices.galvo import SETTINGS, WOBBLE, Command, list_digest, position_of
from insitu.errors import ConfigError, DeviceError, FormatError, SafetyError
from insitu.marking.driver import GalvoDriver
from insitu.marking.job import MarkJob
from insitu.marking.journal import (
    Journal,
    JournalSummary,
    journal_beside,
    progress_path_for,
    read_journal,
    read_progress,
    write_progress,
)

CUT_CHOICES = ("remark", "skip", "continue")
PROGRESS_EVERY_S = 0.5          # the progress record is rewritten at most this often mid-run

__all__ = ["CUT_CHOICES", "RunResult", "history", "progress_path_for", "read_progress",
           "resume_list", "run_job", "run_preview"]


@dataclass(frozen=True)
class RunResult:
    """state: "done" | "cancelled"; ``completed``: paths done or skipped in all runs;
    ``start_path``: the first path this run sent (``total``: none); ``cut``: the cut path
    this run found and ``cut_choice`` what it did with it."""

    state: str
    completed: int
    total: int
    start_path: int
    cut: int | None = None
    cut_choice: str | None = None


def _marks(commands) -> int:
    return sum(c.op == "mark_abs_3d" for c in commands)


def resume_list(commands: list[Command], skip_marks: int) -> list[Command]:
    """A path's list without its first ``skip_marks`` marks (counted over all its passes):
    its settings, the jump of the pass the board stopped in going to where the last skipped
    mark ended, then the laser on, that pass's remaining marks and the passes after it; a
    pass left without marks keeps only its settings. Empty when no mark is left."""
    out: list[Command] = []
    seen, jump = 0, 0
    for c in commands:
        if c.op == "jump_abs_3d":
            jump = len(out)
        if c.op != "mark_abs_3d":
            out.append(c)
            continue
        seen += 1
        if seen <= skip_marks:
            out[jump] = Command("jump_abs_3d", c.args)
            continue
        out.append(c)
    if seen <= skip_marks:
        return []
    starts = [i for i, c in enumerate(out) if c.op == "jump_abs_3d"] + [len(out)]
    kept = out[:starts[0]]
    for a, b in zip(starts, starts[1:]):
        part = out[a:b]
        kept += part if any(c.op == "mark_abs_3d" for c in part) else [
            c for c in part if c.op in SETTINGS or c.op == WOBBLE]
    return kept


def history(job: MarkJob, progress_path: str | Path | None,
            strict: bool = False) -> JournalSummary | None:
    """What earlier runs of ``job`` did, from the journal beside ``progress_path`` (or, for a
    record written before journals, its progress file); None: nothing, or another job there
    (``strict``: FormatError then). FormatError for a malformed journal or progress file."""
    if progress_path is None:
        return None
    ppath, jpath = Path(progress_path), journal_beside(progress_path)
    total, sha = len(job.paths), job.digest()
    s = read_journal(jpath)
    if s is None:
        rec = read_progress(ppath)
        if rec is None or (rec.get("job_sha256") != sha and not strict):
            return None
        read_progress(ppath, sha, total)
        s = JournalSummary(sha, total, done=set(range(rec["completed"])), state=rec["state"],
                           updated=rec.get("updated", ""))
    if s.job_sha256 != sha:
        if strict:
            raise FormatError(f"{jpath}: job_sha256: records another job; start this job from "
                              "the beginning instead of resuming it")
        return None
    if s.paths_total != total:
        raise FormatError(f"{journal_beside(ppath)}: paths_total: {s.paths_total}, but the "
                          f"job has {total} paths")
    return s


def _board_marks(job, driver, controller, s: JournalSummary) -> int | None:
    """Marks of the cut path the board reports done (its last list being that path's)."""
    rec = s.cut_list or {}
    first, skip = rec.get("first"), rec.get("skip_marks", 0)
    if type(first) is not int or not 0 <= first <= s.cut or type(skip) is not int:
        return None
    lists = driver.compile(job, first_path=first)
    cmds, before = lists[s.cut - first], lists[s.cut - first - 1] if s.cut > first else None
    if skip:
        cmds, before = resume_list(driver.compile(job, first_path=s.cut)[0], skip), None
    done = board_done(controller, cmds, before)
    return None if done is None else skip + _marks(cmds[:done])


def board_done(controller, cmds, before=None) -> int | None:
    """Commands of ``cmds`` the board reports done; 0 when its last list is ``before`` (the
    list sent just before ``cmds``), complete — ``cmds`` never reached it (a kill or an abort
    between the journal's "started" and the list); None: the board does not tell."""
    done = position_of(controller, cmds)
    if done is None and before is not None and position_of(controller, before) == len(before):
        return 0
    return done


def _plan(job, driver, controller, s: JournalSummary | None, choice: str | None, where: Path):
    """[(path, list, first, skip_marks)] to send and the cut path's (index, marks) when it is
    left (skip) or found complete (continue)."""
    items, settled = [], None
    todo = s.next_paths() if s is not None else list(range(len(job.paths)))
    if s is not None and s.cut is not None:
        k, total = s.cut, len(job.paths)
        marks = s.cut_position
        if marks is None:
            marks = _board_marks(job, driver, controller, s)
        pos = f" (the board reported {marks} marks done)" if marks is not None else ""
        if choice is None:
            raise SafetyError(f"{where}: path {k + 1} of {total} was started but not confirmed"
                              f"{pos}: choose for the cut path remark (mark it again whole), "
                              "skip (leave it) or continue (from where the board stopped)")
        if choice not in CUT_CHOICES:
            raise ConfigError(f"cut path {choice!r}: expected one of {', '.join(CUT_CHOICES)}",
                              field="cut_path")
        if choice == "remark":
            todo = sorted([k, *todo])
        elif choice == "skip":
            settled = (k, "skipped")
        else:
            if marks is None:
                raise SafetyError(f"cut path continue: the board did not report how far path "
                                  f"{k + 1} got; choose remark or skip")
            rest = resume_list(driver.compile(job, first_path=k)[0], marks)
            if rest:
                items.append((k, rest, k, marks))
            else:
                settled = (k, "done")
    run_start = None
    for i, k in enumerate(todo):                      # contiguous runs compiled together
        if run_start is None or k != todo[i - 1] + 1:
            run_start, lists = k, driver.compile(job, first_path=k)
        items.append((k, lists[k - run_start], run_start, 0))
    return items, settled


def _off(controller, primary: BaseException | None) -> None:
    try:
        controller.laser_off()
    except Exception as e:                          # noqa: BLE001 — a broken controller
        if primary is None:
            raise DeviceError(f"scan head: could not turn the laser off ({e})") from e


def run_job(job: MarkJob, driver: GalvoDriver, controller, progress_path: str | Path | None = None,
            resume: bool = False, cancel: threading.Event | None = None,
            progress: Callable[[int, int], None] | None = None, *, restart: bool = False,
            cut_path: str | None = None) -> RunResult:
    """Mark ``job``, journaled beside ``progress_path`` (None: not recorded).

    Refusals before anything is sent: SafetyError from the driver or the controller's
    :meth:`check` of every list; without ``resume`` or ``restart``, a job whose last run was
    interrupted or cancelled; with ``resume``, a cut path without ``cut_path`` (remark | skip
    | continue; continue only where the board reported its position). ``resume`` marks the
    paths not done; ``restart`` starts again at path 0 (the journal says so). ``cancel``:
    checked between paths. The laser is off however this ends; on an exception the journal
    records the cut path and "interrupted", and the exception propagates.
    """
    if resume and restart:
        raise ConfigError("resume and restart: choose one", field="resume")
    ppath = Path(progress_path) if progress_path is not None else None
    jpath = journal_beside(ppath) if ppath is not None else None
    total, sha = len(job.paths), job.digest()
    s = history(job, ppath, strict=resume)
    if not (resume or restart) and s is not None and s.state != "done" and not s.finished:
        raise SafetyError(f"{jpath}: the last run was {s.state} after {len(s.done)} of {total} "
                          "paths: resume it, or restart it to mark it again from the start")
    s = s if resume else None
    items, settled = _plan(job, driver, controller, s, cut_path, jpath)
    controller.check([cmds for _, cmds, _, _ in items])
    s = s or JournalSummary(sha, total)
    cut = (s.cut, cut_path) if s.cut is not None else (None, None)
    start = items[0][0] if items else total
    if jpath is None:
        return _send(job, controller, items, None, s, None, cancel, progress, start, cut)
    with Journal(jpath) as jr:
        jr.write("begin", job_sha256=sha, paths_total=total,
                 mode="resume" if resume else "restart" if restart else "start")
        if settled is not None:
            (s.done if settled[1] == "done" else s.skipped).add(settled[0])
            jr.write(settled[1], path=settled[0])
        s.cut = s.cut_position = None
        return _send(job, controller, items, jr, s, ppath, cancel, progress, start, cut)


def _send(job, controller, items, jr: Journal | None, s: JournalSummary, ppath, cancel,
          progress, start: int, cut) -> RunResult:
    note = jr.write if jr is not None else (lambda *a, **k: None)
    total = len(job.paths)
    write_progress(ppath, s, "running")
    current, err, last = None, None, time.monotonic()
    try:
        for i, (k, cmds, first, skip) in enumerate(items):
            if cancel is not None and cancel.is_set():
                note("end", state="cancelled", error=None)
                write_progress(ppath, s, "cancelled")
                return RunResult("cancelled", len(s.done | s.skipped), total, start, *cut)
            note("started", path=k, list=list_digest(cmds), first=first, skip_marks=skip)
            current = (k, cmds, skip, items[i - 1][1] if i else None)
            controller.execute(cmds)
            note("done", path=k)
            s.done.add(k)
            current = None
            if time.monotonic() - last >= PROGRESS_EVERY_S:
                write_progress(ppath, s, "running")
                last = time.monotonic()
            if progress:
                progress(len(s.done | s.skipped), total)
        note("end", state="done", error=None)
        write_progress(ppath, s, "done")
        return RunResult("done", len(s.done | s.skipped), total, start, *cut)
    except BaseException as e:
        err = e
        _off(controller, e)
        msg = f"{type(e).__name__}: {e}"
        try:
            if current is not None:
                k, cmds, skip, before = current
                done = board_done(controller, cmds, before)
                marks = None if done is None else skip + _marks(cmds[:done])
                note("cut", path=k, position=marks)
                s.cut, s.cut_position = k, marks
            note("end", state="interrupted", error=msg)
            write_progress(ppath, s, "interrupted", msg)
        except Exception:                           # noqa: BLE001 — the original error matters
            pass
        raise
    finally:
        if err is None:
            _off(controller, None)


def run_preview(job: MarkJob, driver: GalvoDriver, controller,
                outline: str = "hull", speed_mm_s: float = 1000.0, repeat: int = 1) -> None:
    """Draw the job's outline with the pilot laser (see :meth:`GalvoDriver.preview`); the
    laser is off when this returns or raises."""
    cmds = driver.preview(job, outline, speed_mm_s, repeat)
    controller.check([cmds])
    err = None
    try:
        controller.execute(cmds)
    except BaseException as e:
        err = e
        raise
    finally:
        _off(controller, err)
