"""SIGKILL at random moments of marking, then resume, counted against an external truth.

``insitu job run JOB`` on the simulated rig is killed (SIGKILL) at a random moment of its
marking, then ``insitu job run JOB --resume --cut-path …`` runs, and is killed in turn, until
a run completes; then a new job starts. The simulated controller appends every move it executes
to a mark log (``INSITU_SIM_MARK_LOG``): that log, not the journal, is the truth. Per job,
a path is *marked twice in full* when every one of its mark segments is in the log at least
twice, *skipped* when one of them is not in it. A kill is *cut mid-path* when the log's last
list has no end; its cut path is *reported* when the resume's journal names that path.

The cut path's choice (``--choice auto``): continue where the simulated board reports its
position for the cut path's list (the mark log), else remark.

Run: .venv/bin/python benchmarks/kill_resume.py [--kills 200] [--paths 300] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from datetime import datetime
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.marking import history, make_job, progress_path_for, read_job, write_job
from insitu.sim.devices import MARK_LOG_ENV, last_position

CLI = [sys.executable, "-c", "from insitu.cli.main import main; main()"]


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kills", type=int, default=200)
    ap.add_argument("--paths", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--choice", choices=("auto", "remark"), default="auto")
    ap.add_argument("--folder", type=Path, default=None, help="work folder (default: tmp)")
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    folder = a.folder or Path(tempfile.mkdtemp(prefix="kill-resume-",
                                               dir="/dev/shm" if os.access("/dev/shm", os.W_OK)
                                               else None))
    stats, times = Counter(), []
    problems: list[str] = []
    n_job = 0
    t_start = time.perf_counter()
    while stats["kills"] < a.kills:
        n_job += 1
        job_path, ref_log, log = (folder / f"job{n_job}.json", folder / f"ref{n_job}.log",
                                  folder / f"marks{n_job}.log")
        make_test_job(job_path, a.paths, rng)
        job = read_job(job_path)
        # the reference: one clean run on its own log (then its journal is dropped)
        env = {**os.environ, MARK_LOG_ENV: str(ref_log)}
        rc, out = cli(["job", "run", job_path], env)
        assert rc == 0, out
        ref = [segs for _, segs, _ in read_log(ref_log)]
        assert len(ref) == len(job.paths)
        journal = folder / f"job{n_job}.journal.jsonl"
        stamps = [json.loads(line)["time"] for line in journal.read_text().splitlines()]
        mark_s = 1.05 * (_seconds(stamps[-1]) - _seconds(stamps[0]))
        for f in folder.glob(f"job{n_job}.*.json*"):
            f.unlink()
        env = {**os.environ, MARK_LOG_ENV: str(log)}
        args: list = ["job", "run", job_path]
        while True:
            t0 = time.perf_counter()
            rc = kill_at_random(args, env, journal, mark_s, rng)
            times.append(time.perf_counter() - t0)
            if rc == 0:
                break
            stats["kills"] += 1
            s = history(job, progress_path_for(job_path))
            if s is not None and s.finished:
                break                               # killed after its last path
            lists = read_log(log) if log.exists() else []
            mid = bool(lists) and not lists[-1][2]
            stats["cut mid-path"] += mid
            if s is not None and s.cut is not None:
                stats["cut paths reported"] += 1
                if mid and not set(lists[-1][1]) <= set(ref[s.cut]):
                    problems.append(f"job {n_job}: the reported cut path {s.cut} is not the "
                                    "one the board was marking")
            elif mid and lists[-1][1]:
                problems.append(f"job {n_job}: kill mid-path, no cut path reported")
            choice = "remark"
            if s is not None and s.cut is not None and a.choice == "auto":
                pos = last_position(log) if log.exists() else None
                if pos is not None and s.cut_list and pos.digest == s.cut_list.get("list"):
                    choice = "continue"
            stats[choice] += s is not None and s.cut is not None
            args = ["job", "run", job_path, "--resume", "--cut-path", choice]
            if s is None:
                args = ["job", "run", job_path]
            if stats["kills"] >= a.kills:
                rc, out = cli(args, env)
                assert rc == 0, out
                break
        counts = Counter(k for _, segs, _ in read_log(log) for k in segs)
        for k, segs in enumerate(ref):
            need = Counter(segs)
            if all(counts[s] >= 2 * n for s, n in need.items()):
                stats["marked twice in full"] += 1
                problems.append(f"job {n_job}: path {k} marked twice in full")
            if any(counts[s] < n for s, n in need.items()):
                stats["skipped"] += 1
                problems.append(f"job {n_job}: path {k} (partly) never marked")
        stats["jobs"] += 1
        print(f"job {n_job}: {dict(stats)}", flush=True)
    table = Table(title=f"kill & resume: {a.paths}-path jobs on the simulated rig, seed {a.seed}")
    for col in ("kills", "jobs", "cut mid-path", "cut paths reported", "continue", "remark",
                "marked twice in full", "skipped", "mean run time, s"):
        table.add_column(col, justify="right")
    table.add_row(*(str(stats[c]) for c in ("kills", "jobs", "cut mid-path",
                                            "cut paths reported", "continue", "remark",
                                            "marked twice in full", "skipped")),
                  f"{np.mean(times):.2f}")
    Console(width=150).print(table)
    for p in problems:
        print(p)
    print("RESULT " + " ".join(f"{k.replace(' ', '_')}={stats[k]}" for k in (
        "kills", "cut mid-path", "cut paths reported", "marked twice in full", "skipped")))
    print(f"total {time.perf_counter() - t_start:.0f} s; files in {folder}")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
