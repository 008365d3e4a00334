"""SIGKILL at random moments of marking, then resume, counted against an external truth
(tests/integration/test_kill_resume.py runs a few kills, benchmarks/kill_resume.py hundreds).

``insitu job run JOB`` on the simulated rig is killed (SIGKILL) at a random moment of its
marking, then ``insitu job run JOB --resume --cut-path …`` runs, and is killed in turn, until
a run completes; then a new job starts. The simulated controller appends every move it executes
to a mark log (``INSITU_SIM_MARK_LOG``): that log, not the journal, is the truth. Per job,
a path is *marked twice in full* when every one of its mark segments is in the log at least
twice, *skipped* when one of them is not in it. A kill is *cut mid-path* when the log's last
list has no end; its cut path is *reported* when the resume's journal names that path.

The cut path's choice (``auto``): continue where the simulated board reports its position for
the cut path's list (the mark log), else remark. The runs no kill is meant for (each job's clean
reference run, the last resume) run in this process, through the same command.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from insitu.marking import history, make_job, progress_path_for, read_job, write_job
from insitu.sim.controller import MARK_LOG_ENV, last_position

CLI = [sys.executable, "-c", "from insitu.cli.main import main; main()"]


@dataclass
class Campaign:
    """What the kills did: ``stats`` counts kills, jobs, cut mid-path, cut paths reported,
    continue, remark, marked twice in full, skipped; ``problems`` one line each; ``run_s`` the
    duration of each killed or completed run."""

    stats: Counter = field(default_factory=Counter)
    problems: list[str] = field(default_factory=list)
    run_s: list[float] = field(default_factory=list)


def make_test_job(path: Path, n_paths: int, rng) -> None:
    """``n_paths`` wavy strokes of 12 points in a 46 mm square on z = 0."""
    paths = []
    t = np.linspace(0.0, 1.0, 12)
    for _ in range(n_paths):
        x0, y0 = rng.uniform(-20, 20, 2)
        phase = rng.uniform(0, 6)
        paths.append(np.column_stack([x0 + 3 * t, y0 + np.sin(6 * t + phase), 0 * t]))
    write_job(path, make_job(paths))


def read_log(log: Path) -> list[tuple[str, list[str], bool]]:
    """[(list digest, [mark segment keys], ended)] in the order executed."""
    lists = []
    for line in log.read_text().splitlines():
        w = line.split()
        if not w:
            continue
        if w[0] == "L" and len(w) == 3:
            lists.append((w[1], [], False))
        elif w[0] == "M" and lists and len(w) == 8:
            lists[-1][1].append(" ".join(w[2:]))
        elif w[0] == "E" and lists:
            lists[-1] = (lists[-1][0], lists[-1][1], True)
    return lists


def _seconds(stamp: str) -> float:
    return datetime.strptime(stamp, "%Y-%m-%dT%H:%M:%S.%fZ").timestamp()


def cli(args, env, wait=True):
    p = subprocess.Popen(CLI + [str(a) for a in args], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    if wait:
        out, err = p.communicate()
        return p.returncode, out + err
    return p


def run_here(args, log: Path) -> tuple[int, str]:
    """``insitu job run …`` in this process, the simulated controller logging to ``log``:
    (exit code, output)."""
    from typer.testing import CliRunner

    from insitu.cli.main import app

    res = CliRunner().invoke(app, [str(a) for a in args], env={MARK_LOG_ENV: str(log)})
    return res.exit_code, res.output


def kill_at_random(args, env, journal: Path, mark_s: float, rng) -> int:
    """Start ``job run``, SIGKILL it a random time after its journal's first line (or let it
    end); returns the exit code."""
    before = journal.stat().st_size if journal.exists() else 0
    p = cli(args, env, wait=False)
    while p.poll() is None and (not journal.exists() or journal.stat().st_size == before):
        time.sleep(0.002)
    if p.poll() is None:
        time.sleep(rng.uniform(0.0, mark_s))
        if p.poll() is None:
            p.send_signal(signal.SIGKILL)
    p.communicate()
    return p.returncode


def _reference(folder: Path, n_job: int, n_paths: int, rng) -> tuple[Path, list, float]:
    """A new job and one clean run of it on its own log (its journal then dropped): (the job,
    each path's mark segments, the marking's duration in s)."""
    job_path, ref_log = folder / f"job{n_job}.json", folder / f"ref{n_job}.log"
    make_test_job(job_path, n_paths, rng)
    rc, out = run_here(["job", "run", job_path], ref_log)
    assert rc == 0, out
    ref = [segs for _, segs, _ in read_log(ref_log)]
    assert len(ref) == len(read_job(job_path).paths)
    journal = folder / f"job{n_job}.journal.jsonl"
    stamps = [json.loads(line)["time"] for line in journal.read_text().splitlines()]
    for f in folder.glob(f"job{n_job}.*.json*"):
        f.unlink()
    return job_path, ref, 1.05 * (_seconds(stamps[-1]) - _seconds(stamps[0]))


def _after_kill(c: Campaign, job, job_path: Path, log: Path, ref: list, n_job: int,
                choice: str) -> list | None:
    """Counts a kill, checks the cut path it reports; the next run's arguments, None when the
    job was complete."""
    c.stats["kills"] += 1
    s = history(job, progress_path_for(job_path))
    if s is not None and s.finished:
        return None                                     # killed after its last path
    lists = read_log(log) if log.exists() else []
    mid = bool(lists) and not lists[-1][2]
    c.stats["cut mid-path"] += mid
    if s is not None and s.cut is not None:
        c.stats["cut paths reported"] += 1
        if mid and not set(lists[-1][1]) <= set(ref[s.cut]):
            c.problems.append(f"job {n_job}: the reported cut path {s.cut} is not the one the "
                              "board was marking")
    elif mid and lists[-1][1]:
        c.problems.append(f"job {n_job}: kill mid-path, no cut path reported")
    if s is None:
        return ["job", "run", job_path]
    how = "remark"
    if s.cut is not None and choice == "auto":
        pos = last_position(log) if log.exists() else None
        if pos is not None and s.cut_list and pos.digest == s.cut_list.get("list"):
            how = "continue"
    c.stats[how] += s.cut is not None
    return ["job", "run", job_path, "--resume", "--cut-path", how]


def _count(c: Campaign, log: Path, ref: list, n_job: int) -> None:
    counts = Counter(k for _, segs, _ in read_log(log) for k in segs)
    for k, segs in enumerate(ref):
        need = Counter(segs)
        if all(counts[s] >= 2 * n for s, n in need.items()):
            c.stats["marked twice in full"] += 1
            c.problems.append(f"job {n_job}: path {k} marked twice in full")
        if any(counts[s] < n for s, n in need.items()):
            c.stats["skipped"] += 1
            c.problems.append(f"job {n_job}: path {k} (partly) never marked")


def campaign(kills: int, n_paths: int, seed: int, folder: Path, choice: str = "auto",
             on_job: Callable[[Campaign], None] | None = None) -> Campaign:
    """Jobs of ``n_paths`` paths killed and resumed until ``kills`` kills, in ``folder``."""
    rng = np.random.default_rng(seed)
    c, n_job = Campaign(), 0
    while c.stats["kills"] < kills:
        n_job += 1
        job_path, ref, mark_s = _reference(folder, n_job, n_paths, rng)
        job, log = read_job(job_path), folder / f"marks{n_job}.log"
        env = {**os.environ, MARK_LOG_ENV: str(log)}
        args: list | None = ["job", "run", job_path]
        while args is not None:
            t0 = time.perf_counter()
            rc = kill_at_random(args, env, job_path.with_suffix(".journal.jsonl"), mark_s, rng)
            c.run_s.append(time.perf_counter() - t0)
            if rc == 0:
                break
            args = _after_kill(c, job, job_path, log, ref, n_job, choice)
            if args is not None and c.stats["kills"] >= kills:
                rc, out = run_here(args, log)
                assert rc == 0, out
                break
        _count(c, log, ref, n_job)
        c.stats["jobs"] += 1
        if on_job:
            on_job(c)
    return c
