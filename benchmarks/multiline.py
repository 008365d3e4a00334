"""Several lines per exposure against one line per frame (issue 32, items 1–2).

For each part and setting of insitu's simulator, the same scan (lines 0.5 mm apart) once with
one line per frame and once packed (``--lines-per-frame auto``: a survey frame bounds the
heights, then as many lines per exposure as their bands allow, about 8 mm apart on the step
block): height RMS and max error over the part's top against the simulator's truth, the top's
coverage, the points on a wrongly identified line, the frames and the station seconds (the
scan's station seconds on the full-size rig: benchmarks/multiline_clock.py).

Wrong line: each point's centre (the point seen by the true camera) must lie nearer its own
line's true stripe (the true beam's hits on the true scene that the true camera sees) than
any other line's drawn in the same exposure.

Independent recordings (/work/shared/recordings, another renderer): none holds `lines` frames
(checked and printed); their step block's single-line frames are summed into frames of lines
≥ 8 mm apart (light adds: the sum is K lines drawn in a K-times exposure, the room light K
times, clipped as the camera clips) with a survey frame first, and replayed through the same
code as a recording of `lines` frames; truth.json scores only. A K-line exposure reads the
sensor once: the sum less K − 1 dark offsets (INDEPENDENT_DARK_DN). Its read noise and
rounding stay those of K reads (√K × one read's): they cannot be taken out of the frames.
The recordings hold no laser-off frame (the arc's ambient.png is not its frames' room light:
its fine texture correlates 0.27 with theirs), so rows "+ laser-off" make one per K from the
recording itself — the dark offset plus K × the per-pixel median of every third one-line
frame above it, shot noise drawn at truth.json's gain — and give the frames their exposure
(K × 50 ms): the replay subtracts (K − 1)/K of it as a live scan does.

Hold-out: the packing's margins (reconstruct.bands.Packing) were set on the step block at
binning 4, seed 11; every other row (binning 2, seed 5 with Method 1, the other parts, the
independent frames) was run only after. Settings 1 and 2 are spent.

Renders (``--renders tune|held-out|S,S``): the rig of a setting (its seed: camera, head,
operator's calibration) with the world drawn from other seeds (noise, speckle, texture), one
row per seed and part, and the ratio also on the points both scans measured. TUNE_RENDERS
may be run at will; HELD_OUT_RENDERS are run once, on the final code, then marked spent here.

Run: nice .venv/bin/python benchmarks/multiline.py [--parts step-block,arc,...]
         [--settings 1 --renders tune --no-independent]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from accuracy import coverage, height_errors, on_top  # noqa: E402
from independent import coverage as coverage_lines  # noqa: E402
from independent import errors, true_part  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from insitu.formats.calibration import HeightCalibration  # noqa: E402
from insitu.formats.json_file import load_json_model, save_json_model  # noqa: E402
from insitu.formats.sequence import Sequence  # noqa: E402
from insitu.formats.sequence_writer import SequenceWriter  # noqa: E402
from insitu.geometry.beams import line_commands  # noqa: E402
from insitu.reconstruct.bands import Packing, Sheets, survey  # noqa: E402
from insitu.reconstruct.packing import line_ids  # noqa: E402
from insitu.services import calibrate_height, camera_model, scan_live, scan_replay  # noqa: E402
from insitu.services.scan import plan_lines  # noqa: E402
from insitu.services.station import simulated  # noqa: E402
from insitu.sim.rig import default_rig  # noqa: E402
from insitu.sim.world import SimWorld, workpiece_at  # noqa: E402
from insitu.vision.extract import CentreSettings  # noqa: E402

console = Console(width=160)
ROOT = Path(__file__).resolve().parents[1]
PARTS = ("step-block", "arc", "insert", "tilted-plane", "freeform")
SETTINGS = (   # (binning, seed, height calibration): the first tuned the margins
    (4, 11, ROOT / "tests/data/height-cal-b4"),
    (2, 11, ROOT / "tests/data/height-cal-b2.json"),
    (2, 5, None),
)
INDEPENDENT_DARK_DN = 3.0   # the other renderer's dark offset: its arc's frames (per-pixel
# median of 7) against its ambient.png (482 ms, the frames 50 ms) give 2.7-3.3 DN (the
# intercept of the room light's line, with or without an offset in ambient.png)
TUNE_RENDERS = (101, 102, 103, 104, 105, 106, 107, 108)   # world seeds, run at will
SPENT_RENDERS = (201, 202, 203,   # held out, run once on 79183bf (docs/speed.md)
                 204, 205, 206,   # held out, run once on 52b954a / 441811d (docs/speed.md)
                 207, 208, 209)   # held out, run once on 0eb8866 (insert, step block)
HELD_OUT_RENDERS = (210, 211, 212)   # declared 2026-12-05 before any run; not yet run


def calibration(source: Path | None, cache: Path) -> HeightCalibration | None:
    """The fitted height calibration of a recording (cached) or a fitted file."""
    if source is None:
        return None
    if source.suffix == ".json":
        return load_json_model(source, HeightCalibration)
    path = cache / f"{source.name}.json"
    if not path.exists():
        save_json_model(path, calibrate_height(source))
    return load_json_model(path, HeightCalibration)


def true_stripe(world, a, b) -> np.ndarray:
    """(M, 2) px: where the true camera sees the true beam of the line a → b hit the true
    scene (samples 0.02 mm apart along the line, the hits it can see)."""
    n = int(np.linalg.norm(np.subtract(b, a)) / 0.02) + 2
    origins, dirs = world.rig.beams.rays(line_commands(a, b, n))
    scene, cam = world.renderer().scene, world.rig.camera
    hits = scene.cast(origins, dirs)
    p, nrm = hits.points[hits.hit], hits.normals[hits.hit]
    seen = scene.visible_from(p, nrm, cam.centre_world)
    return cam.project(p[seen])


def wrong_line(world, cloud, frames: dict) -> int:
    """Points whose centre lies nearer the true stripe of another line drawn in the same
    exposure than its own line's (``frames``: line id → (its (start, end), the frame's
    lines (start, end) each)). Each point's centre: the point seen by the true camera (the
    operator's calibration moves it by far less than the stripes lie apart)."""
    line = cloud.attributes["line"].astype(int)
    uv = world.rig.camera.project(cloud.points)
    bad, stripes = 0, {}
    for k in np.unique(line):
        own, group = frames[int(k)]
        if len(group) < 2:
            continue
        at = line == k
        d = {}
        for g in group:
            key = (tuple(g[0]), tuple(g[1]))
            if key not in stripes:
                stripes[key] = cKDTree(true_stripe(world, *g))
            d[key] = stripes[key].query(uv[at])[0]
        mine = d[(tuple(own[0]), tuple(own[1]))]
        bad += int(np.sum(mine > np.min(np.array(list(d.values())), axis=0) + 1e-9))
    return bad


def run_scan(part: str, binning: int, seed: int, cal, per_frame, render: int | None = None):
    """One live scan on a fresh simulated world (the rig of ``seed``, the world's draws of
    ``render``, default ``seed``): (result, world, line id → (its line, the lines of the
    frame that measured it))."""
    world = SimWorld(default_rig(seed=seed, binning=binning), parts=[workpiece_at(part)],
                     seed=seed if render is None else render)
    station = simulated(world)
    groups: list[list] = []
    head = station.devices.head
    show = head.show_lines

    def spy(lines, focus_z=0.0):
        groups.append([_key(a, b) for a, b in lines])
        show(lines, focus_z)
    head.show_lines = spy
    head.show_line = lambda a, b, focus_z=0.0: spy([(a, b)], focus_z)
    result = scan_live(station, 0.5, height_cal=cal, lines_per_frame=per_frame)
    lines = plan_lines(station.default_region(), 0.5)
    frame_of = {line: g for g in groups for line in g}   # survey frames first: a line's
    return result, world, {k: (_key(a, b), frame_of[_key(a, b)])   # last frame measured it
                           for k, (a, b) in zip(line_ids(lines), lines)}


def _key(a, b) -> tuple:
    """A drawn line as ((x, y), (x, y)) floats, its ends in order (either direction)."""
    return tuple(sorted((tuple(map(float, a)), tuple(map(float, b)))))


def score(result, world, frames) -> dict:
    """RMS, max, coverage, wrong-line points of a scan's cloud against the world's truth."""
    part, cloud, s = world.parts[0], result.cloud, result.summary
    _, e = height_errors(part, cloud)
    return {"rms": float(np.sqrt(np.mean(e ** 2))), "max": float(np.max(np.abs(e))),
            "cov": coverage(part, cloud), "wrong": wrong_line(world, cloud, frames),
            "frames": s.camera_frames, "station": s.station_s, "cpu": s.cpu_s,
            "packing": s.packing, "keys": _keys(part, cloud)}


def _keys(part, cloud) -> dict:
    """Height errors of the points over the part's top by (line, y to 0.1 mm): the same
    place measured by two scans has the same key."""
    ok, z = on_top(part, cloud.points)
    p, line = cloud.points[ok], cloud.attributes["line"][ok].astype(np.int64)
    y = np.round(p[:, 1] / 0.1).astype(np.int64)
    return dict(zip((line * 100000 + y).tolist(), (p[:, 2] - z[ok]).tolist()))


def both_rms(a: dict, b: dict) -> tuple[float, float, int]:
    """RMS of two scans' errors over the places both measured, and how many."""
    both = np.intersect1d(list(a), list(b))
    ea, eb = np.array([a[k] for k in both]), np.array([b[k] for k in both])
    return float(np.sqrt(np.mean(ea ** 2))), float(np.sqrt(np.mean(eb ** 2))), len(both)


def renders_table(parts, setting, renders, cache: Path) -> None:
    """One line per frame against packed on the rig of ``setting`` with the world drawn
    from each of ``renders``: the distribution of packed / one-line RMS."""
    binning, seed, source = setting
    cal = calibration(source, cache)
    print("part | render | RMS 1 / packed (×) | on both (×, n) | max 1 / packed | "
          "coverage 1 / packed | wrong | frames", flush=True)
    for part in parts:
        ratios, both = [], []
        for render in renders:
            a, b = (score(*run_scan(part, binning, seed, cal, pf, render))
                    for pf in (None, "auto"))
            ra, rb, n = both_rms(a["keys"], b["keys"])
            ratios.append(b["rms"] / a["rms"])
            both.append(rb / ra)
            print(f"{part} | {render} | {a['rms']:.4f} / {b['rms']:.4f} ({ratios[-1]:.2f}) | "
                  f"{ra:.4f} / {rb:.4f} ({both[-1]:.2f}, {n}) | {a['max']:.3f} / "
                  f"{b['max']:.3f} | {a['cov']:.1%} / {b['cov']:.1%} | {b['wrong']} | "
                  f"{a['frames']} / {b['frames']}", flush=True)
        print(f"{part}: × one line median {np.median(ratios):.2f}, range {min(ratios):.2f}–"
              f"{max(ratios):.2f}; on both median {np.median(both):.2f}, range "
              f"{min(both):.2f}–{max(both):.2f}", flush=True)


def simulator_table(parts, settings, cache: Path) -> None:
    t = Table(title="insitu's simulator: lines 0.5 mm apart, one line per frame (1) against "
                    "packed (auto); heights over the top ≥ 1 mm from walls, truth-scored")
    for col in ("part", "binning/seed/method", "lines/frame", "frames", "RMS mm", "×1",
                "max mm", "coverage", "wrong-line pts", "station s", "×1 station",
                "CPU s", "packing"):
        t.add_column(col)
    for binning, seed, source in settings:
        cal = calibration(source, cache)
        method = "Method 2" if cal is not None else "Method 1"
        for part in parts:
            base = None
            for per_frame in (None, "auto"):
                s = score(*run_scan(part, binning, seed, cal, per_frame))
                base = base or s
                row = (part, f"{binning}/{seed}/{method}", str(per_frame or 1),
                       str(s["frames"]), f"{s['rms']:.4f}", f"{s['rms'] / base['rms']:.2f}",
                       f"{s['max']:.3f}", f"{s['cov']:.1%}", str(s["wrong"]),
                       f"{s['station']:.3f}", f"{s['station'] / base['station']:.3f}",
                       f"{s['cpu']:.2f}", s["packing"])
                print(" | ".join(row), flush=True)       # as it comes: the runs are long
                t.add_row(*row)
    console.print(t)


def independent_table(folder: Path, cache: Path) -> None:
    """Which independent recordings hold `lines` frames (printed); then their scans'
    single-line frames summed into frames of lines ≥ 8 mm apart, replayed against the
    recordings themselves (see the module docstring)."""
    t = Table(title=f"independent recordings in {folder}: frames with `lines`")
    for col in ("recording", "frames", "with lines"):
        t.add_column(col)
    for seq in sorted(folder.glob("*/sequence.json")):
        frames = json.loads(seq.read_text())["frames"]
        t.add_row(seq.parent.name, str(len(frames)), str(sum("lines" in f for f in frames)))
    console.print(t)
    hcal = folder / "height-calibration-coarse-independent"
    cal = calibrate_height(hcal, CentreSettings())
    t = Table(title="independent renderer: its one-line frames (1) against the same frames "
                    "summed into frames of lines ≥ 8 mm apart (packed), replayed; Method 2 "
                    f"from {hcal.name}; truth-scored, tops ≥ 1 mm from walls")
    for col in ("recording", "lines/frame", "frames", "points", "RMS mm", "×1", "max mm",
                "coverage", "> 1.5 mm off the surface"):
        t.add_column(col)
    for name in ("step-block-independent", "arc-posed-independent"):
        src = folder / name
        truth = json.loads((src / "truth.json").read_text())
        part = true_part(truth) if truth["workpiece"]["name"] == "step-block" else PosedArc(truth)
        xs = sorted({f.line.start[0] for f in Sequence.open(src).frames})
        base = None
        gain = truth["render"]["gain_e_per_dn"]
        for label, rec in (
                ("1", src), ("packed", summed(src, cache / name)),
                ("packed + laser-off", summed(src, cache / f"{name}-off", gain=gain)),
                ("8 a frame", summed(src, cache / f"{name}-8", most=8)),
                ("8 a frame + laser-off", summed(src, cache / f"{name}-8-off", most=8,
                                                 gain=gain))):
            res = scan_replay(rec, cal)
            pts = res.cloud.points
            e = errors(part, pts, 1.0)
            rms = float(np.sqrt(np.mean(e ** 2)))
            base = base or rms
            t.add_row(name, label, str(len(Sequence.open(rec))), f"{len(pts):,}",
                      f"{rms:.4f}", f"{rms / base:.2f}", f"{np.abs(e).max():.3f}",
                      f"{coverage_lines(part, pts, xs):.1%}", str(off_surface(part, pts)))
    console.print(t)


class PosedArc:
    """The independent arc as its README describes it (40 × 40 mm, 11.5 mm crown, 3 mm at
    x = ±20 of its frame), placed by truth.json's pose: ``height(x, y)`` world mm (NaN off
    it) and ``bounds()``."""

    def __init__(self, truth: dict):
        x, y, angle = truth["workpiece"]["pose"]
        self.t, self.a = np.array([x, y]), np.radians(angle)
        self.R = (20.0 ** 2 + 8.5 ** 2) / (2 * 8.5)

    def height(self, x, y):
        c, s = np.cos(self.a), np.sin(self.a)
        dx, dy = np.asarray(x) - self.t[0], np.asarray(y) - self.t[1]
        px, py = c * dx + s * dy, -s * dx + c * dy
        z = 11.5 - self.R + np.sqrt(np.maximum(self.R ** 2 - px ** 2, 0.0))
        return np.where((np.abs(px) <= 20) & (np.abs(py) <= 20), z, np.nan)

    def bounds(self):
        r = 20.0 * np.sqrt(2)
        return self.t - r, self.t + r


def off_surface(part, pts: np.ndarray, tol: float = 1.5) -> int:
    """Points farther than ``tol`` mm in height from the true surface (the table where the
    part is not) within 0.3 mm of them: a centre on a wrong line puts its point millimetres
    off."""
    best = np.full(len(pts), np.inf)
    for dx in (-0.3, 0.0, 0.3):
        for dy in (-0.3, 0.0, 0.3):
            z = part.height(pts[:, 0] + dx, pts[:, 1] + dy)
            best = np.minimum(best, np.abs(pts[:, 2] - np.where(np.isfinite(z), z, 0.0)))
    return int(np.sum(best > tol))


def summed(src: Path, out: Path, gap_mm: float = 8.0, most: int = Packing().most_lines,
           dark_dn: float = INDEPENDENT_DARK_DN, gain: float | None = None) -> Path:
    """``src``'s frames summed less K − 1 dark offsets ``dark_dn`` (one read of the sensor;
    clipped to the camera's range) into frames of at most ``most`` lines ≥ ``gap_mm`` apart
    (as ``auto`` packs), after survey frames of lines as far apart as the head's focus range
    needs (:func:`insitu.reconstruct.bands.survey`): a recording of `lines` frames.
    ``gain`` (e⁻/DN): with the frames' exposures and a laser-off frame of each K's
    (:func:`laser_off`)."""
    seq = Sequence.open(src)
    frames = seq.frames
    xs = [f.line.start[0] for f in frames]
    sheets = Sheets(camera_model(seq.camera), seq.scan_head.pivot_height_mm)
    order = list(np.argsort(xs))
    bands = [sheets.band(*frames[i].drawn()[0], tuple(seq.scan_head.z_range_mm), 1.0)
             for i in order]
    groups: list[list[int]] = []
    for i in order:
        for g in groups:
            if len(g) < most and all(abs(xs[i] - xs[j]) >= gap_mm for j in g):
                g.append(i)
                break
        else:
            groups.append([i])
    surveys = [[order[j] for j in f] for f in survey(bands, 1.0)]
    top = 2 ** (seq.pixel_bits or 8) - 1
    dtype, exposure = seq.read_frame(0).dtype, frames[0].exposure_ms
    with SequenceWriter(out, "scan", seq.scan_head.model_dump(),
                        camera=seq.camera.model_dump(), pixel_bits=seq.pixel_bits) as w:
        if seq.ambient is not None:
            w.add_ambient(seq.read_ambient(), seq.ambient.exposure_ms)
        if gain is not None:
            for k in sorted({len(g) for g in groups if len(g) > 1}):
                off = laser_off(seq, k, dark_dn, gain, np.random.default_rng(k))
                w.add_ambient(np.clip(off, 0, top).astype(dtype), k * exposure, packed=True)
        for g, is_survey in [(g, True) for g in surveys] + [(g, False) for g in groups]:
            img = sum(seq.read_frame(i).astype(np.float64) for i in g)
            img = np.clip(np.rint(img - (len(g) - 1) * dark_dn), 0, top).astype(dtype)
            lines = [frames[i].line.model_dump() for i in g]
            many = {"lines": lines} if len(lines) > 1 else {"line": lines[0]}
            timed = {"exposure_ms": len(g) * exposure} if gain is not None else {}
            w.add(img, **many, **timed, **({"survey": True} if is_survey else {}))
    return out


def laser_off(seq, k: int, dark_dn: float, gain: float, rng) -> np.ndarray:
    """(H, W) float DN: a laser-off frame of ``k`` exposures of ``seq``'s room light — the
    dark offset plus k × the per-pixel median of every third frame above it (each pixel is
    off the line in most), its shot noise drawn (Poisson at ``gain`` e⁻/DN), rounded."""
    room = np.median(np.stack([seq.read_frame(i) for i in range(0, len(seq), 3)]), axis=0)
    electrons = np.maximum(k * (room - dark_dn), 0.0) * gain
    return np.rint(dark_dn + rng.poisson(electrons) / gain)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default=",".join(PARTS))
    ap.add_argument("--settings", default="0,1,2", help="indices into SETTINGS (none: '')")
    ap.add_argument("--no-independent", action="store_true")
    ap.add_argument("--renders", default="", help="tune, held-out or seeds: the world drawn "
                    "from each, the rig of the one setting given")
    ap.add_argument("--recordings", type=Path, default=ROOT.parents[1] / "shared" / "recordings")
    args = ap.parse_args()
    cache = Path(tempfile.gettempdir()) / "insitu-multiline-bench"
    cache.mkdir(exist_ok=True)
    if not args.no_independent:
        independent_table(args.recordings, cache)
    if args.renders:
        named = {"tune": TUNE_RENDERS, "held-out": HELD_OUT_RENDERS}
        renders = named.get(args.renders) or [int(x) for x in args.renders.split(",")]
        renders_table(args.parts.split(","), SETTINGS[int(args.settings)], renders, cache)
    elif args.settings:
        simulator_table(args.parts.split(","),
                        [SETTINGS[int(i)] for i in args.settings.split(",")], cache)


if __name__ == "__main__":
    main()
