#!/usr/bin/env python3
"""Rewrite tests/data/golden_small_job.txt from the driver's current command stream.

Run it only after reviewing a deliberate change of that stream; then review the diff of the
file (git diff tests/data) and commit both. The test never writes the file.
Usage: PYTHONPATH=src python scripts/regen-golden.py
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from golden import GOLDEN, mark_small_job  # noqa: E402

from insitu.formats.atomic import atomic_write_text  # noqa: E402

result, rc = mark_small_job()
if result.state != "done" or result.completed != 2:
    sys.exit(f"regen-golden: the small job did not finish ({result.state}, {result.completed} "
             "of 2 paths); nothing written")
old = GOLDEN.read_text() if GOLDEN.exists() else ""
atomic_write_text(GOLDEN, rc.listing())
print(f"{GOLDEN}: {'unchanged' if old == rc.listing() else 'rewritten'} "
      f"({len(rc.listing().splitlines())} commands)")
