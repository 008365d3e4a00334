"""Measurement on recordings made by another renderer than ours (``shared/recordings``): the
height calibration fitted from the recorded plate, the scan replayed through exactly the code
a live scan runs, scored against the recording's ``truth.json`` (read here only).

For each scan recording (kind ``scan``) with a height-calibration recording beside it:
Method 2 as the paper (P1 + P2, gray centroid) and ours (light-sheet model, Steger, smoothed
along the line as long as the frame's own speckle needs, wrong lines dropped), height error
over the part's top ≥ 0.3 and ≥ 1 mm from walls, the points removed, and how much of the top
is covered (1 mm cells with a point).

Run: .venv/bin/python benchmarks/independent.py [RECORDINGS_DIR]   (default ../shared/recordings)
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table
from scipy.spatial import cKDTree

from insitu.formats.sequence import Sequence
from insitu.services import calibrate_height, scan_replay
from insitu.sim.workpieces import make_workpiece
from insitu.vision.extract import PAPER_SETTINGS, CentreSettings

console = Console(width=150)
DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "recordings"


def true_part(truth: dict):
    """The recording's part as one of our catalogue's (for its height function); None for a
    part this benchmark has no scorer for (benchmarks/locate_independent.py scores the arc)."""
    w = truth["workpiece"]
    if w["name"] != "step-block":
        return None
    p = w["params"]
    return make_workpiece("step-block", length=p["y_size"], width=p["x_size"],
                          heights=p["heights"], x=p["center"][0], y=p["center"][1])


def errors(part, points, margin):
    """(N,) height errors of the points over the part's top ≥ ``margin`` mm from any wall."""
    z = part.height(points[:, 0], points[:, 1])
    ok = np.isfinite(z) & (z > 0.5)
    for dx, dy in ((margin, 0), (-margin, 0), (0, margin), (0, -margin)):
        zn = part.height(points[:, 0] + dx, points[:, 1] + dy)
        ok &= np.isfinite(zn) & (np.abs(zn - z) < 0.3)
    return points[ok, 2] - z[ok]


def coverage(part, points, lines_x, cell=1.0):
    """Fraction of 1 mm cells of the top, along the scanned lines, that hold a point."""
    xs = np.asarray(lines_x)
    lo, hi = part.bounds()
    ys = np.arange(lo[1] + cell / 2, hi[1], cell)
    gx, gy = (g.ravel() for g in np.meshgrid(xs, ys))
    z = part.height(gx, gy)
    top = np.isfinite(z) & (z > 0.5)
    d, _ = cKDTree(points[:, :2]).query(np.column_stack([gx[top], gy[top]]))
    return float(np.mean(d < cell / 2))


def main() -> None:
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT
    folders = sorted(p.parent for p in root.glob("*/sequence.json"))
    scans = [f for f in folders if Sequence.open(f).kind == "scan"]
    hcals = [f for f in folders if Sequence.open(f).kind == "height-calibration"]
    if not scans or not hcals:
        raise SystemExit(f"{root}: needs a scan and a height-calibration recording")
    t = Table(title=f"independent recordings ({root}): height error over the top, mm")
    for col in ("scan", "method", "points", "removed", "RMS ≥0.3", "max ≥0.3", "RMS ≥1",
                "max ≥1", "top covered", "time"):
        t.add_column(col)
    for scan in scans:
        part = true_part(json.loads((scan / "truth.json").read_text()))
        if part is None:
            console.print(f"{scan.name}: no height scorer for its part, left out")
            continue
        xs = sorted({f.line.start[0] for f in Sequence.open(scan).frames})
        for name, settings in (("paper", PAPER_SETTINGS), ("sheet", CentreSettings())):
            cal = calibrate_height(hcals[0], settings)
            t0 = time.perf_counter()
            result = scan_replay(scan, cal, name)
            dt = time.perf_counter() - t0
            pts, s = result.cloud.points, result.summary
            e3, e1 = errors(part, pts, 0.3), errors(part, pts, 1.0)
            t.add_row(scan.name, name, f"{s.points:,}",
                      f"{s.outliers_removed} + {s.unconfirmed_removed}",
                      f"{np.sqrt(np.mean(e3**2)):.4f}", f"{np.abs(e3).max():.3f}",
                      f"{np.sqrt(np.mean(e1**2)):.4f}", f"{np.abs(e1).max():.3f}",
                      f"{coverage(part, pts, xs):.1%}", f"{dt:.1f} s")
    console.print(t)
    console.print(f"height calibration from {hcals[0].name}; 'removed': isolated + "
                  "unconfirmed by the neighbouring lines")


if __name__ == "__main__":
    main()
