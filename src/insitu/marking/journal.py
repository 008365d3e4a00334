"""The journal of what the laser did: ``<job>.journal.jsonl`` beside the job, append-only,
one JSON object per line, each line flushed and ``os.fsync``'ed before the run goes on.

Events (``"event"``; every line also has ``"time"``, ISO-8601 UTC):
  ``begin``   ``job_sha256``, ``paths_total``, ``mode``: "start" | "resume" | "restart"
              (a "start" or "restart" forgets every earlier event)
  ``started`` ``path`` k — written before path k's list is sent; ``list``: its digest, ``first``
              and ``skip_marks``: how it was made (see :mod:`insitu.marking.run`)
  ``done``    ``path`` k — written after the controller confirmed path k
  ``cut``     ``path`` k, ``position``: marks (mark moves) of path k the board reported done,
              or null when it reports nothing
  ``skipped`` ``path`` k — the operator chose to leave a cut path as it is
  ``end``     ``state``: "done" | "cancelled" | "interrupted", ``error`` (text or null)

A path started and neither done nor skipped is a *cut path*: the laser may have marked part of
it. A run without an ``end`` line was killed.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.validation import read_json

EVENTS = ("begin", "started", "done", "cut", "skipped", "end")
STATES = ("done", "cancelled", "interrupted")


def journal_path_for(job_path: str | Path) -> Path:
    """``parts/job.json`` → ``parts/job.journal.jsonl``."""
    p = Path(job_path)
    return p.with_name(p.stem + ".journal.jsonl")


def now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


@dataclass
class JournalSummary:
    """What a journal says. ``done``: paths confirmed (or skipped: ``skipped``); ``cut``: the
    path started and not confirmed (None: none), ``cut_position`` the marks of it the board
    reported done (None: not known) and ``cut_list`` its ``started`` line (how its list was
    made: ``first``, ``skip_marks``, ``list`` digest); ``state``: the last run's end, or
    "killed" when it has none; ``updated``: time of the last line; ``runs``: runs recorded
    since the last start or restart."""

    job_sha256: str
    paths_total: int
    done: set[int] = field(default_factory=set)
    skipped: set[int] = field(default_factory=set)
    cut: int | None = None
    cut_position: int | None = None
    state: str = "killed"
    error: str | None = None
    updated: str = ""
    runs: int = 0
    cut_list: dict | None = None

    @property
    def finished(self) -> bool:
        """Every path done or skipped."""
        return len(self.done | self.skipped) >= self.paths_total

    def next_paths(self) -> list[int]:
        """Paths still to mark, in order, without the cut path."""
        return [k for k in range(self.paths_total)
                if k not in self.done and k not in self.skipped and k != self.cut]


def _int(path: Path, line: int, rec: dict, key: str, total: int | None) -> int:
    v = rec.get(key)
    if type(v) is not int or v < 0 or (total is not None and v >= total):
        bound = f"0 … {total - 1}" if total is not None else "≥ 0"
        raise FormatError(f"{path}: line {line}: {key}: expected an integer {bound}, got {v!r}")
    return v


def read_journal(path: str | Path) -> JournalSummary | None:
    """The summary of the journal at ``path`` (None: no journal). FormatError naming the file,
    line and field of a malformed line; a last line cut short by a kill is ignored."""
    path = Path(path)
    if not path.exists():
        return None
    try:
        lines = path.read_bytes().decode("utf-8").split("\n")
    except (OSError, UnicodeDecodeError) as e:
        raise FormatError(f"{path}: cannot read the journal ({e})") from None
    s: JournalSummary | None = None
    started: set[int] = set()
    position: dict[int, int] = {}
    lists: dict[int, dict] = {}
    for i, text in enumerate(lines, 1):
        if not text.strip():
            continue
        try:
            rec = json.loads(text)
        except json.JSONDecodeError:
            if i == len(lines):                 # the line a kill cut short (no newline yet)
                break
            raise FormatError(f"{path}: line {i}: not JSON") from None
        ev = rec.get("event") if isinstance(rec, dict) else None
        if ev not in EVENTS:
            raise FormatError(f"{path}: line {i}: event: expected one of {', '.join(EVENTS)}, "
                              f"got {ev!r}")
        if ev == "begin":
            total, sha = rec.get("paths_total"), rec.get("job_sha256")
            if type(total) is not int or total < 0:
                raise FormatError(f"{path}: line {i}: paths_total: expected an integer ≥ 0, "
                                  f"got {total!r}")
            if not isinstance(sha, str):
                raise FormatError(f"{path}: line {i}: job_sha256: expected a string")
            if s is None or rec.get("mode") != "resume" or s.job_sha256 != sha:
                s, started, position = JournalSummary(sha, total), set(), {}
                lists = {}
            s.runs += 1
            s.state, s.error = "killed", None
        elif s is None:
            raise FormatError(f"{path}: line {i}: {ev} before any begin")
        elif ev == "end":
            if rec.get("state") not in STATES:
                raise FormatError(f"{path}: line {i}: state: expected one of "
                                  f"{', '.join(STATES)}, got {rec.get('state')!r}")
            s.state, s.error = rec["state"], rec.get("error")
        else:
            k = _int(path, i, rec, "path", s.paths_total)
            if ev == "started":
                started.add(k)
                position.pop(k, None)
                lists[k] = rec
            elif ev == "done":
                s.done.add(k)
            elif ev == "skipped":
                s.skipped.add(k)
            elif rec.get("position") is not None:                       # cut
                position[k] = _int(path, i, rec, "position", None)
        s.updated = rec.get("time", s.updated)
    if s is None:
        raise FormatError(f"{path}: no begin line: not an insitu journal")
    cut = sorted(started - s.done - s.skipped)
    s.cut = cut[0] if cut else None
    s.cut_position = position.get(s.cut)
    s.cut_list = lists.get(s.cut)
    return s


class Journal:
    """Appends events to the journal file; every line is on disk when :meth:`write` returns."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def write(self, event: str, **fields) -> None:
        line = json.dumps({"event": event, **fields, "time": now()}) + "\n"
        os.write(self._fd, line.encode())
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def __enter__(self) -> Journal:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ------------------------------------------------------------------ progress record
PROGRESS_FORMAT = "insitu-job-progress/1"
PROGRESS_STATES = ("running", "interrupted", "cancelled", "done")


def progress_path_for(job_path: str | Path) -> Path:
    """``parts/job.json`` → ``parts/job.progress.json``."""
    p = Path(job_path)
    return p.with_name(p.stem + ".progress.json")


def journal_beside(progress_path: str | Path) -> Path:
    """The journal beside a progress record: ``job.progress.json`` → ``job.journal.jsonl``."""
    p = Path(progress_path)
    name = p.name[:-len(".progress.json")] if p.name.endswith(".progress.json") else p.stem
    return p.with_name(name + ".journal.jsonl")


def read_progress(path: str | Path, job_sha256: str | None = None,
                  paths_total: int | None = None) -> dict | None:
    """The progress record (None: there is none). FormatError naming the file and field when
    it is not one — ``state`` missing or unknown, ``completed`` not an integer (a bool is
    not) or outside 0 … ``paths_total`` — or records another job than ``job_sha256`` /
    ``paths_total`` (when given)."""
    path = Path(path)
    if not path.exists():
        return None
    d = read_json(path)
    if not isinstance(d, dict) or d.get("format") != PROGRESS_FORMAT:
        raise FormatError(f"{path}: not a job progress file ({PROGRESS_FORMAT})")
    if d.get("state") not in PROGRESS_STATES:
        raise FormatError(f"{path}: state: expected one of {', '.join(PROGRESS_STATES)}, got "
                          f"{d.get('state')!r}")
    total = d.get("paths_total")
    if type(total) is not int or total < 0:
        raise FormatError(f"{path}: paths_total: expected an integer ≥ 0, got {total!r}")
    done = d.get("completed")
    if type(done) is not int or not 0 <= done <= total:
        raise FormatError(f"{path}: completed: expected an integer 0 … {total}, got {done!r}")
    if job_sha256 is not None and d.get("job_sha256") != job_sha256:
        raise FormatError(f"{path}: job_sha256: records another job; delete it to start this "
                          "job from the beginning")
    if paths_total is not None and total != paths_total:
        raise FormatError(f"{path}: paths_total: {total}, but the job has {paths_total} paths")
    return d


def write_progress(path: Path | None, s: JournalSummary, state: str,
                   error: str | None = None) -> None:
    """The progress record of ``s`` (atomically): ``completed`` = the paths before the first
    one neither done nor skipped, ``cut_path`` / ``cut_position`` as the journal says."""
    if path is None:
        return
    handled = s.done | s.skipped
    completed = next((k for k in range(s.paths_total) if k not in handled), s.paths_total)
    rec = {"format": PROGRESS_FORMAT, "job_sha256": s.job_sha256, "paths_total": s.paths_total,
           "completed": completed, "last_completed_path": completed - 1 if completed else None,
           "done_paths": len(s.done), "skipped_paths": sorted(s.skipped),
           "cut_path": s.cut, "cut_position": s.cut_position, "state": state, "error": error,
           "updated": now()}
    atomic_write_text(path, json.dumps(rec, indent=1) + "\n")
