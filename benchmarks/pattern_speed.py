"""Speed of turning patterns into ordered polylines, one core.

The target case (issue): a 30 × 30 mm QR code hatched at 0.04 mm must become ordered
polylines well under 1 s (the whole job including projection must stay under 2 s). Prints a
table: case, polylines, mark length, jump length (ordered, and for the plain scan-line order
for comparison), and time (median of rounds) for load + place, and for hatch + order.
Run: .venv/bin/python benchmarks/pattern_speed.py
"""

from __future__ import annotations

import os
import statistics
import time
from pathlib import Path

os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core, honestly

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from insitu.patterns import hatch, jump_length, load_pattern  # noqa: E402
from insitu.patterns.fill import hatch_segments  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
QR = 'qr:"https://example.com/insitu/part/0042-A7"'
CASES = [  # (name, spec, width mm, hatch kwargs)
    ("QR 30 mm @ 0.04 (Case 3 fine)", QR, 30.0, dict(spacing_mm=0.04)),
    ("QR 30 mm @ 0.12 (Case 3 coarse)", QR, 30.0, dict(spacing_mm=0.12)),
    ("QR 30 mm @ 0.04 cross", QR, 30.0, dict(spacing_mm=0.04, cross=True)),
    ("QR 30 mm @ 0.04 one-way", QR, 30.0, dict(spacing_mm=0.04, bidirectional=False)),
    ("QR 30 mm @ 0.04 45°", QR, 30.0, dict(spacing_mm=0.04, angle_deg=45.0)),
    ("text 40 mm @ 0.04", 'text:"insitu 0042"', 40.0, dict(spacing_mm=0.04)),
    ("logo.svg 30 mm @ 0.04", str(ROOT / "patterns/logo.svg"), 30.0, dict(spacing_mm=0.04)),
    ("part.dxf 40 mm @ 0.04", str(ROOT / "patterns/part.dxf"), 40.0, dict(spacing_mm=0.04)),
    ("qr.png 30 mm @ 0.04", str(ROOT / "patterns/qr.png"), 30.0, dict(spacing_mm=0.04)),
]


def scanline_jump(pattern, spacing_mm, angle_deg=0.0, bidirectional=True, **_) -> float:
    """Jump length of the plain order: line by line (back and forth if ``bidirectional``),
    no blocks, no 2-opt."""
    k, xa, xb, y, rot = hatch_segments(pattern.contours, spacing_mm, angle_deg)
    segs = []
    for line in np.unique(k):
        i = np.flatnonzero(k == line)
        s = [np.array([[xa[j], y[j]], [xb[j], y[j]]]) @ rot.T for j in i]
        segs += s if line % 2 == 0 or not bidirectional else [q[::-1] for q in s[::-1]]
    return jump_length(segs)


def timed(fn, rounds):
    times, out = [], None
    for _ in range(rounds):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, statistics.median(times)


def main(rounds: int = 5) -> None:
    table = Table(title=f"pattern → ordered polylines (median of {rounds}, one core)")
    for col in ("case", "polylines", "mark mm", "jump mm", "scan-line jump mm",
                "load+place ms", "hatch+order ms"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for name, spec, width, kw in CASES:
        placed, t_load = timed(lambda s=spec, w=width: load_pattern(s).placed((0.0, 0.0), w),
                               rounds)
        polys, t_hatch = timed(lambda p=placed, k=kw: hatch(p, **k), rounds)
        mark = sum(float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in polys)
        table.add_row(name, f"{len(polys)}", f"{mark:.0f}", f"{jump_length(polys):.0f}",
                      f"{scanline_jump(placed, **kw):.0f}" if not kw.get("cross") else "",
                      f"{t_load * 1e3:.1f}", f"{t_hatch * 1e3:.1f}")
    Console(width=150).print(table)


if __name__ == "__main__":
    main()
