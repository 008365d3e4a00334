"""Why a frame of several lines measured worse than one line a frame (issue 32): each
suspect isolated by drawing the same lines on insitu's simulator in variants of one frame.

For every frame of the packed scan (``--lines-per-frame auto``, the heights from the one-line
scan ± 2 mm as a survey gives them), each line's centres are found in its own band
(:func:`~insitu.vision.band_centres.centres_in_bands`, the bands of its frame made
exclusive) in:

- one line a frame — its own frame, measured as the scan measures it (``add``): the baseline;
- the same frame in the packed frame's band: the band, its clipping, the sheets' lookup;
- the K lines' light with one line's room light: the other lines' stray light and halos;
- the line alone with K exposures of room light: the room light of the longer exposure;
- the K lines as the scan draws them (K exposures of room light);
- the same less the texture of (K − 1)/K of a laser-off frame of its exposure (what the
  scan does, :func:`~insitu.reconstruct.scan.excess_room_light`).

Truth-scored (height RMS and max over the top, coverage). Tune half: binning 4, seed 11 (the
held-out rows are benchmarks/multiline.py's binning 2).

Run: nice .venv/bin/python benchmarks/multiline_why.py [--parts tilted-plane,freeform]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from accuracy import coverage, height_errors, on_top  # noqa: E402
from multiline import calibration  # noqa: E402

from insitu.reconstruct.bands import Packing, exclusive  # noqa: E402
from insitu.reconstruct.packing import FramePlan  # noqa: E402
from insitu.reconstruct.scan import excess_room_light, less_room_light  # noqa: E402
from insitu.services.scan import plan_lines, reconstructor  # noqa: E402
from insitu.services.station import simulated  # noqa: E402
from insitu.sim.world import sim_world  # noqa: E402
from insitu.vision.band_centres import centres_in_bands  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXPOSURE_MS = 10.0


def variants(r, one):
    """(label, image of line k of frame f) for each suspect; ``r`` the world's renderer,
    ``one`` the one-line frames by line."""
    cache: dict = {}

    def packed(f, light_of):
        key = (f.ids, light_of)
        if key not in cache:
            k = len(f.lines)
            if light_of == "scan":
                cache[key] = r.lines_frame(f.lines, EXPOSURE_MS * k)
            elif light_of == "one":
                signal = sum(r._line_signal(a, b, EXPOSURE_MS, 0.0) for a, b in f.lines)
                cache[key] = r._finish(signal, EXPOSURE_MS)
            else:
                image = packed(f, "scan")
                off = excess_room_light(r.ambient_frame(EXPOSURE_MS * k), k)
                cache[key] = less_room_light(image, off)
        return cache[key]

    def alone_k(f, k):
        return r._finish(r._line_signal(*f.lines[k], EXPOSURE_MS, 0.0),
                         EXPOSURE_MS * len(f.lines))

    return [("its own frame, in the packed band", lambda f, k: one[f.ids[k]]),
            ("K lines' light, one line's room light", lambda f, k: packed(f, "one")),
            ("the line alone, K exposures' room light", alone_k),
            ("K lines as the scan draws them", lambda f, k: packed(f, "scan")),
            ("the same less (K − 1)/K of a laser-off frame", lambda f, k: packed(f, "less"))]


def _keys(cloud, part) -> dict:
    """The height errors of the points over the part's top by (line, y to 0.1 mm): the
    same place measured by two scans has the same key."""
    ok, z = on_top(part, cloud.points)
    p, line = cloud.points[ok], cloud.attributes["line"][ok].astype(np.int64)
    y = np.round(p[:, 1] / 0.1).astype(np.int64)
    return dict(zip((line * 100000 + y).tolist(), (p[:, 2] - z[ok]).tolist()))


def part_rows(part_name: str, cal) -> list[tuple]:
    world = sim_world(part_name, seed=11, binning=4)
    station = simulated(world)
    rig, part, r = station.rig, world.parts[0], world.renderer()
    lines = plan_lines(station.default_region(), 0.5)

    def new():
        return reconstructor(rig.camera, rig.head.pivot_height_mm, False, rig.head.z_range_mm,
                             cal, None, "why")

    base: list = []

    def scored(label, rec):
        cloud = rec.cloud()
        _, e = height_errors(part, cloud)
        keys = _keys(cloud, part)
        base.append(base[0] if base else keys)
        both = np.intersect1d(list(base[0]), list(keys))
        pair = (np.array([base[0][k] for k in both]), np.array([keys[k] for k in both]))
        return (part_name, label, float(np.sqrt(np.mean(e ** 2))), float(np.abs(e).max()),
                coverage(part, cloud), *(float(np.sqrt(np.mean(x ** 2))) for x in pair))

    rec, one = new(), {}
    for i, (a, b) in enumerate(lines):
        one[i] = r.line_frame(a, b, EXPOSURE_MS)
        rec.add(i, one[i], a, b)
    rows = [scored("one line a frame", rec)]
    z = rec.cloud().points[:, 2]
    plan = FramePlan(lines, rec.sheets, rig.head.z_range_mm, "auto")
    frames = plan.frames((float(np.percentile(z, 0.1)), float(np.percentile(z, 99.9))))
    p = Packing()
    for label, image_of in variants(r, one):
        rec = new()
        for f in frames:
            bands = exclusive([rec.sheets.band(a, b, plan.z_range, p.margin_px)
                               for a, b in f.lines], p.guard_px)
            for k, ((a, b), line_id) in enumerate(zip(f.lines, f.ids)):
                c = centres_in_bands(image_of(f, k), [bands[k]], rec.settings, p.edge_px,
                                     rec.pixel_bits)[0]
                rec._store(int(line_id), a, b, c)
        rows.append(scored(label, rec))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="tilted-plane,freeform")
    args = ap.parse_args()
    cache = Path(tempfile.gettempdir()) / "insitu-multiline-bench"
    cache.mkdir(exist_ok=True)
    cal = calibration(ROOT / "tests/data/height-cal-b4", cache)
    t = Table(title="why packed frames measured worse: simulator, binning 4, seed 11 (tune "
                    "half), lines 0.5 mm apart, up to 4 a frame; truth-scored")
    for col in ("part", "each line's frame", "RMS mm", "× one line", "max mm", "coverage",
                "where both measured: RMS one line / this"):
        t.add_column(col)
    for part in args.parts.split(","):
        rows = part_rows(part, cal)
        for name, label, rms, top, cov, rms_one, rms_this in rows:
            t.add_row(name, label, f"{rms:.4f}", f"{rms / rows[0][2]:.2f}", f"{top:.3f}",
                      f"{cov:.1%}", f"{rms_one:.4f} / {rms_this:.4f} = "
                                    f"{rms_this / rms_one:.2f}")
    Console(width=140).print(t)


if __name__ == "__main__":
    main()
