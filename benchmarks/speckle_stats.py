"""Laser-line statistics of real photographs beside our simulator's frames.

For each set of real images (the image paths given, grouped by folder) and for simulated line frames
on a metal part (step block) and a matte one (calibration plate), at 5 ms (unsaturated), prints the
medians over the images of: along-line coefficient of variation (integrated cross-profile), its 1/e
autocorrelation length in px and mm, the gamma shape k, line σ, saturation, background level,
texture and shading, and secondary peaks within ±60 px (:mod:`insitu.sim.linestats`). Real images'
mm scale: from a checkerboard in view (``--pattern``, ``--square-mm``), if found.

Run: .venv/bin/python benchmarks/speckle_stats.py [IMAGE|FOLDER ...] [--binning 2] [--frames 4]
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.sim.linestats import LineStats, line_stats
from insitu.sim.rig import default_rig
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld

COLUMNS = ("n", "cv", "corr_px", "corr_mm", "gamma_k", "width_px", "saturated", "background",
           "texture", "shading", "secondary_p95", "secondary_frac")


def board_mm_per_px(img: np.ndarray, pattern: tuple[int, int], square_mm: float) -> float:
    """mm per px from the median spacing of a checkerboard's inner corners, NaN if none."""
    gray = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    ok, corners = cv2.findChessboardCorners(gray, pattern)
    if not ok:
        return np.nan
    c = corners.reshape(pattern[1], pattern[0], 2)
    step = np.concatenate([np.linalg.norm(np.diff(c, axis=0), axis=2).ravel(),
                           np.linalg.norm(np.diff(c, axis=1), axis=2).ravel()])
    return square_mm / float(np.median(step))


def real_sets(paths: list[str], pattern, square_mm) -> dict[str, list[tuple[LineStats, float]]]:
    files = []
    for p in map(Path, paths):
        files += sorted(q for q in p.iterdir() if q.suffix.lower() in (".jpg", ".png")) \
            if p.is_dir() else [p]
    sets = defaultdict(list)
    for f in files:
        img = cv2.imread(str(f))
        if img is None:
            continue
        sets[f.parent.name].append((line_stats(img), board_mm_per_px(img, pattern, square_mm)))
    return sets


def sim_sets(binning: int, frames: int) -> dict[str, list[tuple[LineStats, float]]]:
    """Line frames along y on the step block's 10 mm step and on the plate, default optics."""
    rig = default_rig(seed=5, binning=binning)
    out = {}
    for label, world, z in (("sim metal (step block)",
                             SimWorld(rig, parts=[make_workpiece("step-block")], seed=5), 10.0),
                            ("sim matte (plate)", SimWorld(rig, plate_z=0.0, seed=5), 0.0)):
        r = world.renderer()
        rows = []
        for i in range(frames):
            x = -6.0 + 12.0 * i / max(frames - 1, 1)
            y0, y1 = (1.0, 19.0) if z == 10.0 else (-40.0, 40.0)
            img = r.line_frame([x, y0], [x, y1], exposure_ms=5.0, focus_z=z)  # unsaturated
            a, b = rig.camera.project(np.array([[x, 10.0, z], [x, 11.0, z]]))
            rows.append((line_stats(img, along="u", bright_only=False), 1.0 / float(np.linalg.norm(b - a))))
        out[label] = rows
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("images", nargs="*", help="real laser-line photographs or folders of them")
    ap.add_argument("--binning", type=int, default=2)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--pattern", default="8x6", help="checkerboard inner corners, COLSxROWS")
    ap.add_argument("--square-mm", type=float, default=40.0)
    a = ap.parse_args()
    pattern = tuple(int(v) for v in a.pattern.split("x"))
    sets = {**real_sets(a.images, pattern, a.square_mm), **sim_sets(a.binning, a.frames)}
    table = Table(title="laser line along-line statistics (medians over images)")
    table.add_column("set")
    table.add_column("images")
    for c in COLUMNS:
        table.add_column(c)
    for name, rows in sets.items():
        used = [(s, mm) for s, mm in rows if s.n >= 30]
        if not used:
            table.add_row(name, f"0/{len(rows)}", *["–"] * len(COLUMNS))
            continue
        vals = {k: np.nanmedian([getattr(s, k) for s, _ in used])
                for k in LineStats.__dataclass_fields__}
        mm = np.array([mm for _, mm in used])
        vals["corr_mm"] = (np.nanmedian([s.corr_px * m for s, m in used])
                           if np.isfinite(mm).any() else np.nan)
        table.add_row(name, f"{len(used)}/{len(rows)}",
                      *[f"{vals[c]:.3g}" if np.isfinite(vals[c]) else "–" for c in COLUMNS])
    Console(width=200).print(table)


if __name__ == "__main__":
    main()
