"""A pocket plate measured once, the simulator's settings varied: how far the measured depth of
each pocket (``marking.engrave_depth``: its floor against the top of the same lines, no height
calibration) is from the truth the simulator removed (``SimWorld.true_depth``, never read by
the code under test).

The plate: four 2 × 2 mm pockets (``--size 6``: the issue's 6 × 6 mm) 0.05, 0.1, 0.2 and
0.5 mm deep cut straight into a blank (walls tapered over 30 µm), 3 mm apart along x
(:func:`centres_x`), scanned once (lines along y, 0.1 mm apart)
and each pocket mapped from that one scan. The settings varied: the rig's seed (its camera,
calibration errors, speckle and noise), the sensor's noise (read noise × 3, a third of the
electrons per DN), the image speckle's contrast (0.35 → 0.6), the exposure (5 and 20 ms
against 10), the binning (2 × 2) and the blank's material. Each variation of a seed draws its
own speckle and sensor noise (:func:`own_draws`; the base row the renderer's own stream), so a
seed's eight rows are eight independent draws on one rig and plate. Every variation runs on
each seed of a half (``--half``): seed 0 tunes; seeds 5, 7, 9, 21, 31, 33, 41, 43, 45, 47, 49,
51, 53, 55, 57, 59, 61, 63, 65, 67, 69 and 71 were held out and are spent, so they tune too; :data:`HELD_OUT` was fixed before
anything was run on it, to be run once on the final code (seed 11 is not used here: the
engraving loop spent it).

A pocket's depth is stated only when its standard error (the floor's lines as independent
samples or, where larger, the scatter along them; the top's own and the lines' shared one
beside it) puts it within
±5 µm at 2σ
(:meth:`~insitu.marking.engrave_depth.DepthMap.pocket_depth`); the others are scored too,
marked ✗.

The other renderer's pocket plate is not in /work/shared/recordings (the recordings there are
listed); only our simulator is scored here.

Run: nice .venv/bin/python benchmarks/engrave_plate.py [--half tune|spent|held|held-coarse] [--seed N]
[--only NAME] [--spacing MM] [--draws N] [--size MM] [--taper MM] [--cross]
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
import shapely
from rich.console import Console
from rich.table import Table

from insitu.marking.engrave_depth import DepthSettings, measure_depth
from insitu.marking.engrave_passes import combine, line_passes
from insitu.marking.engrave_stats import SHARED_MM
from insitu.marking.engrave_walls import viewpoints
from insitu.services.pocket import DEPTH_CENTRES
from insitu.services.scan import scan_live
from insitu.services.station import simulated
from insitu.sim.pocket_plate import DEPTHS, SIZE_MM, TAPER_MM, centres_x, cut_plate, pocket_truth
from insitu.sim.rig import default_rig
from insitu.sim.world import sim_world
from insitu.vision.extract import CentreSettings

RECORDINGS = Path("/work/shared/recordings")
TOLERANCE = 0.005
SPACING_MM = 0.1
DRAWS = 0xD4A
"""The tag of the variations' random streams (:func:`own_draws`)."""
console = Console(width=160)

# name, blank, optics changed, binning, exposure ms (None: the camera's own)
VARIATIONS = [
    ("base", "blank-stainless", {}, 1, None),
    ("noise × 3", "blank-stainless", {"read_noise_dn": 3.6, "electrons_per_dn": 2.7}, 1, None),
    ("speckle 0.6", "blank-stainless", {"speckle_contrast": 0.6}, 1, None),
    ("exposure 5 ms", "blank-stainless", {}, 1, 5.0),
    ("exposure 20 ms", "blank-stainless", {}, 1, 20.0),
    ("binning 2", "blank-stainless", {}, 2, None),
    ("anodised", "blank-anodised", {}, 1, None),
    ("beech", "blank-beech", {}, 1, None),
]
TUNE = (0,)
SPENT = (5, 7, 9, 21, 31, 33, 41, 43, 45, 47, 49, 51, 53, 55, 57, 59, 61, 63, 65, 67, 69, 71)
"""Held out before and looked at: they tune now (9 and 21 run once on 4bb92d8, 31 and 33 on
f08d089, 41 and 43 on f7116a9, 45 and 47 on 6ab7c44, 49 and 51 on d47dbf0, 53 and 55 at
``--size`` 2 and 6 on 2bb76da, 61 and 63 base and beech at ``--taper`` 0.03 and 0.3 on
37884bd, 57 and 59 at ``--size`` 2 and 6 on 4462aa8, 69 and 71 at ``--spacing`` 0.5 and 1
on 780f010, 65 and 67 at ``--size`` 2 and 6 on 14d80e0)."""
HELD_OUT = (77, 79)
"""Fixed before any result on them was seen; run once, every variation, at both sizes
(``--size`` 2 and 6), at the end, on the final code."""
HELD_OUT_COARSE = (73, 75)
"""Fixed before any result on them was seen: lines 0.5 and 1 mm apart (``--spacing``; the
floor of a 2 mm pocket holds 2–3 lines, not stated), ``--size`` 2 at 0.5 and 6 at both,
every variation; run once, at the end, on the final code."""
SEEDS = {"tune": TUNE, "spent": SPENT, "held": HELD_OUT, "held-coarse": HELD_OUT_COARSE}


def own_draws(world, seed: int, draw: int) -> None:
    """Give ``world``'s renderer the random stream of ``draw`` (> 0) of ``seed``: its own
    speckle field and frame offsets, blotches along the lines, ray jitter and sensor noise;
    the rig, the scene and the plate stay the seed's. Draw 0 keeps the renderer's own
    stream. Call before the first frame (the speckle field is made then)."""
    if draw:
        world.renderer().rng = np.random.default_rng([seed, DRAWS, draw])


def measure_plate(blank: str, seed: int, optics: dict, binning: int,
                  exposure_ms: float | None, draw: int = 0, spacing_mm: float = SPACING_MM,
                  cross: bool = False, size_mm: float = SIZE_MM,
                  taper_mm: float = TAPER_MM):
    """(depth, measured mean, its standard error, stated to :data:`TOLERANCE`, true mean) mm
    of each pocket from one scan of the plate, lines ``spacing_mm`` apart, the renderer's
    random numbers those of ``draw`` (:func:`own_draws`); the scan's station time, s; and
    each pocket's (error, standard error) mm from each pass. With ``cross`` a second pass
    of crossed lines (:func:`~insitu.services.scan.plan_lines`): each pass
    (:func:`~insitu.marking.engrave_passes.line_passes`) measured on its own
    (:func:`measure_depth` takes one line direction), their means weighted by their inverse
    variances (:func:`~insitu.marking.engrave_passes.combine`); stated when both passes
    have 8 lines on the floor and 2σ is within :data:`TOLERANCE`. ``size_mm``, ``taper_mm``:
    the pockets' side and how far their walls slope (:func:`cut_plate`)."""
    rig = default_rig(seed=seed, binning=binning)
    rig = replace(rig, optics=replace(rig.optics, **optics))
    s = DepthSettings(ring_mm=1.5)
    half, cxs = size_mm / 2, centres_x(size_mm)
    region = (cxs.min() - half - 2, cxs.max() + half + 2, -half - s.ring_mm, half + s.ring_mm)
    with simulated(sim_world(blank, seed=seed, rig=rig)) as st:
        own_draws(st.world, seed, draw)
        cut_plate(st.world, taper_mm=taper_mm, size_mm=size_mm)
        scan = scan_live(st, spacing_mm, region, centres=CentreSettings(**DEPTH_CENTRES),
                         room_light=False, exposure_ms=exposure_ms, cross=cross)
        pts, line = scan.cloud.points, scan.cloud.attributes["line"]
        on = [p.holds(line) for p in line_passes(pts[:, :2], line)]
        out, passes, truths = [], [], pocket_truth(st.world, taper_mm)
        for k, (cx, depth) in enumerate(zip(cxs, DEPTHS)):
            near = np.abs(pts[:, 0] - cx) <= half + s.ring_mm
            pocket = shapely.box(cx - half, -half, cx + half, half)
            each = [_pocket(pts[near & p], line[near & p], pocket, s, st.rig) for p in on]
            mean, sem, stated = combined(each)
            truth = truths[k]["true_mean_mm"]
            out.append((depth, mean, sem, stated, truth))
            passes.append([(m - truth, e) for m, e, _ in each])
    return out, scan.summary.station_s, passes


def combined(each: list[tuple[float, float, bool]]) -> tuple[float, float, bool]:
    """(mean, standard error mm, stated) of a pocket from its passes' (mean, standard error,
    enough lines) measured on their own (:func:`~insitu.marking.engrave_passes.combine`, the
    error the lines share, :data:`~insitu.marking.engrave_stats.SHARED_MM`, common to both),
    stated when every pass has enough lines and 2σ is within :data:`TOLERANCE`."""
    mean, sem = combine([(m, e) for m, e, _ in each], SHARED_MM)
    return mean, sem, all(ok for _, _, ok in each) and 2 * sem <= TOLERANCE


def _pocket(pts: np.ndarray, line: np.ndarray, pocket, s: DepthSettings, rig
            ) -> tuple[float, float, bool]:
    """(measured mean depth, its standard error mm, enough lines on the floor) of ``pocket``
    from one pass's points (N, 3) and their lines (N,)."""
    dm = measure_depth(pts, line, pocket, s, viewpoints=viewpoints(rig))
    mean, sem = dm.mean_depth()
    return mean, sem, dm.floor_lines >= 8


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=tuple(SEEDS), default="tune",
                    help="which seeds: tune (0), spent (tune too), held (held out), "
                    "held-coarse (held out for lines 0.5 and 1 mm apart)")
    ap.add_argument("--seed", type=int, help="only this seed of the half")
    ap.add_argument("--only", action="append", help="only the runs of this name")
    ap.add_argument("--spacing", type=float, default=SPACING_MM,
                    help="the scan lines' spacing, mm")
    ap.add_argument("--draws", type=int, default=1,
                    help="scans of each row, each with its own draws")
    ap.add_argument("--size", type=float, default=SIZE_MM,
                    help="the pockets' side, mm (6: the issue's 6 × 6 mm pockets)")
    ap.add_argument("--taper", type=float, default=TAPER_MM,
                    help="how far the pockets' walls slope across, mm")
    ap.add_argument("--cross", action="store_true",
                    help="a second pass of crossed lines over the plate, each pass measured "
                    "on its own and their depths combined")
    args = ap.parse_args()
    t = Table(title=f"measured pocket depth − truth ± its 1σ, µm; ✗: not stated to ±5 µm "
              f"(2σ) (insitu's simulator, one scan a plate of {args.size:g} mm pockets, lines "
              f"{args.spacing:g} mm apart"
              f"{', a crossed pass' if args.cross else ''})")
    for col in ("settings", "blank", "seed", "draw", *(f"{d:g} mm" for d in DEPTHS),
                "station s"):
        t.add_column(col, justify="right")
    rows = []
    seeds = [s for s in SEEDS[args.half] if args.seed in (None, s)]
    for seed in seeds:
        for k, (name, blank, optics, binning, exposure) in enumerate(VARIATIONS):
            if args.only and name not in args.only:
                continue
            for j in range(args.draws):
                draw = k + len(VARIATIONS) * j
                r, station_s, passes = measure_plate(blank, seed, optics, binning, exposure,
                                                     draw, args.spacing, args.cross,
                                                     args.size, args.taper)
                rows += [((m - tr) * 1e3, sem * 1e3, ok) for _, m, sem, ok, tr in r]
                t.add_row(name, blank, str(seed), str(draw),
                          *(f"{(m - tr) * 1e3:+.1f} ±{sem * 1e3:.1f}{'' if ok else ' ✗'}"
                            for _, m, sem, ok, tr in r), f"{station_s:.1f}")
                console.print(f"{name} {blank} seed {seed} draw {draw} size {args.size:g} mm "
                              f"taper {args.taper:g} mm spacing {args.spacing:g} mm, station {station_s:.1f} s: {r}; "
                              f"each pass's (error, σ): {passes}", highlight=False)
    console.print(t)
    err, sem, ok = (np.array(c) for c in zip(*rows))
    near = np.abs(err) <= TOLERANCE * 1e3
    console.print(f"{args.half} (seeds {seeds}): {len(err)} pockets, {near.sum()} "
                  f"within {TOLERANCE * 1e3:g} µm, largest |error| {np.abs(err).max():.1f} µm; "
                  f"stated {ok.sum()}, of them within {TOLERANCE * 1e3:g} µm {(near & ok).sum()};"
                  f" |error|/σ rms {np.sqrt(np.mean((err / sem) ** 2)):.2f}, within 2σ "
                  f"{np.mean(np.abs(err) <= 2 * sem) * 100:.0f} %; error rms "
                  f"{np.sqrt(np.mean(err ** 2)):.2f} µm, σ rms {np.sqrt(np.mean(sem ** 2)):.2f}"
                  " µm", highlight=False)
    folders = sorted(p.name for p in RECORDINGS.iterdir() if p.is_dir())
    console.print(f"the other renderer's recordings ({RECORDINGS}): {', '.join(folders)}; none "
                  "holds a pocket plate, so it is not scored here", highlight=False)


if __name__ == "__main__":
    main()
