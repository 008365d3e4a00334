"""Fuzz every reader with mutated valid files (the engine: tests/fuzzing.py); not run in CI
(tests/unit/test_fuzz_readers.py runs a few hundred examples with the run's seed).

Prints a table: reader, examples, ok, refused, failures, hangs (+ crashes), max and mean ms,
then the first failures with the command that repeats each.

Run: .venv/bin/python benchmarks/fuzz.py --examples 10000 [--seed N] [--readers dxf,svg]
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from fuzzing import READERS, run_reader  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--examples", type=int, default=10_000, help="examples per reader")
    ap.add_argument("--seed", type=int, default=None, help="default: random, printed")
    ap.add_argument("--readers", default=",".join(READERS), help="comma-separated names")
    ap.add_argument("--timeout", type=float, default=10.0, help="seconds: longer is a hang")
    ap.add_argument("--start", type=int, default=0, help="first example index (to repeat one)")
    a = ap.parse_args()
    seed = a.seed if a.seed is not None else random.randrange(10**9)
    names = [s for s in a.readers.split(",") if s]
    unknown = [s for s in names if s not in READERS]
    if unknown:
        raise SystemExit(f"--readers: unknown {unknown}; known: {', '.join(READERS)}")
    print(f"seed {seed}, {a.examples} examples per reader, timeout {a.timeout:g} s")
    rows, t0 = [], time.time()
    for name in names:
        st = run_reader(name, seed, a.examples, a.timeout, a.start)
        rows.append(st)
        print(f"  {name}: {st.examples} in {time.time() - t0:.0f} s", flush=True)
    head = ("reader", "examples", "ok", "refused", "failures", "hangs", "max ms", "mean ms")
    print("\n| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    for st in rows:
        print(f"| {st.name} | {st.examples} | {st.ok} | {st.refused} | "
              f"{len(st.failures) - st.hangs} | {st.hangs} | {st.max_ms:.0f} | "
              f"{st.total_ms / max(st.examples - st.hangs, 1):.1f} |")
    for st in rows:
        print(f"{st.name}: slowest #{st.slowest[0]} ({st.slowest[1]}), {st.max_ms:.0f} ms")
        for k, how, what in st.failures[:5]:
            print(f"{st.name} #{k} ({how}): {what}\n  repeat: benchmarks/fuzz.py --readers "
                  f"{st.name} --seed {seed} --start {k} --examples 1")


if __name__ == "__main__":
    main()
