"""The serial counter under contention: P processes each take S serials from one counter file
(lock, read, issue with fsync); every serial must be handed out exactly once. Prints the
serials taken, duplicates and gaps, and the time per serial (one process alone, then racing).
Run: .venv/bin/python benchmarks/serials.py [--processes 4] [--each 50]
"""

from __future__ import annotations

import argparse
import multiprocessing
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from insitu.formats.counter import locked, read_counter


def take(path: Path, count: int, queue) -> None:
    got = []
    for _ in range(count):
        with locked(path) as c:
            n = c.next
            c.issue(n, job="bench.json", digest="-")
        got.append(n)
    queue.put(got)


def run(path: Path, processes: int, each: int) -> tuple[list[int], float]:
    with locked(path) as c:
        c.set_next(1, force=True)
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=take, args=(path, each, queue)) for _ in range(processes)]
    t0 = time.perf_counter()
    for p in procs:
        p.start()
    got = [n for _ in procs for n in queue.get()]
    dt = time.perf_counter() - t0
    for p in procs:
        p.join()
    return got, dt


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--processes", type=int, default=4)
    ap.add_argument("--each", type=int, default=50)
    a = ap.parse_args()
    table = Table(title="serial counter: every serial once")
    for col in ("processes", "serials", "distinct", "duplicates", "gaps", "next", "ms / serial"):
        table.add_column(col, justify="right")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "serial.counter.json"
        for procs in (1, a.processes):
            got, dt = run(path, procs, a.each)
            want = set(range(1, procs * a.each + 1))
            table.add_row(str(procs), str(len(got)), str(len(set(got))),
                          str(len(got) - len(set(got))), str(len(want - set(got))),
                          str(read_counter(path).next), f"{dt / len(got) * 1e3:.2f}")
    Console().print(table)
    print("(ms / serial includes starting the processes)")


if __name__ == "__main__":
    main()
