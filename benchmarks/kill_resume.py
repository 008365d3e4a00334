"""SIGKILL at random moments of marking, then resume, counted against an external truth: the
campaign of tests/kill_campaign.py (its docstring says what is counted) over many kills.

Run: .venv/bin/python benchmarks/kill_resume.py [--kills 200] [--paths 300] [--seed 0]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from kill_campaign import campaign  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kills", type=int, default=200)
    ap.add_argument("--paths", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--choice", choices=("auto", "remark"), default="auto")
    ap.add_argument("--folder", type=Path, default=None, help="work folder (default: tmp)")
    a = ap.parse_args()
    folder = a.folder or Path(tempfile.mkdtemp(prefix="kill-resume-",
                                               dir="/dev/shm" if os.access("/dev/shm", os.W_OK)
                                               else None))
    t_start = time.perf_counter()
    c = campaign(a.kills, a.paths, a.seed, folder, a.choice,
                 on_job=lambda done: print(f"job {done.stats['jobs']}: {dict(done.stats)}",
                                         flush=True))
    stats = c.stats
    table = Table(title=f"kill & resume: {a.paths}-path jobs on the simulated rig, seed {a.seed}")
    for col in ("kills", "jobs", "cut mid-path", "cut paths reported", "continue", "remark",
                "marked twice in full", "skipped", "mean run time, s"):
        table.add_column(col, justify="right")
    table.add_row(*(str(stats[k]) for k in ("kills", "jobs", "cut mid-path",
                                            "cut paths reported", "continue", "remark",
                                            "marked twice in full", "skipped")),
                  f"{np.mean(c.run_s):.2f}")
    Console(width=150).print(table)
    for p in c.problems:
        print(p)
    print("RESULT " + " ".join(f"{k.replace(' ', '_')}={stats[k]}" for k in (
        "kills", "cut mid-path", "cut paths reported", "marked twice in full", "skipped")))
    print(f"total {time.perf_counter() - t_start:.0f} s; files in {folder}")
    sys.exit(1 if c.problems else 0)


if __name__ == "__main__":
    main()
