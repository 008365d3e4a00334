"""Where the application keeps the jobs of a project never saved, each with its journal from
the first "started" (:mod:`insitu.marking.journal`), so that ABORT, a fault or a killed
application leaves a job that Resume finishes: one file per job, named by its digest, in the
working folder (beside the application's settings file, ``unsaved/``). Finished jobs beyond
the newest few are removed; an unfinished one is never."""

from __future__ import annotations

from pathlib import Path

from insitu.errors import InsituError
from insitu.marking import MarkJob, journal_path_for, progress_path_for, read_journal

KEEP_FINISHED = 10
PREFIX = "unsaved-"
SUFFIX = ".job.json"


def unsaved_job_path(folder: Path, job: MarkJob) -> Path:
    """The job file of ``job`` in the working ``folder`` (its journal beside it)."""
    return Path(folder) / f"{PREFIX}{job.digest()[:16]}{SUFFIX}"


def is_unsaved_job(path: Path | None, folder: Path) -> bool:
    """Is ``path`` a job file of the working ``folder``?"""
    return path is not None and Path(path).parent == Path(folder)


def _finished(job_path: Path) -> bool:
    """Does the journal beside ``job_path`` say every path was done (or nothing ran)?"""
    try:
        s = read_journal(journal_path_for(job_path))
    except InsituError:
        return False                    # a journal that cannot be read is kept, never lost
    return s is None or (s.state == "done" and s.finished)


def prune(folder: Path, keep: int = KEEP_FINISHED) -> list[Path]:
    """Remove the finished jobs of ``folder`` (with their journals and progress records)
    beyond the ``keep`` newest; returns the job files removed."""
    jobs = sorted(Path(folder).glob(f"{PREFIX}*{SUFFIX}"), key=lambda p: p.stat().st_mtime,
                  reverse=True)
    gone = [p for p in jobs[keep:] if _finished(p)]
    for p in gone:
        for f in (p, journal_path_for(p), progress_path_for(p)):
            f.unlink(missing_ok=True)
    return gone
