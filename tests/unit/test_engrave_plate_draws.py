"""benchmarks/engrave_plate.py: each variation of a seed draws its own speckle and noise, so a
seed's eight rows are eight independent results (from one stream, the read noise × 3 row would
be the base row's draws scaled: their flat top's residuals correlate 0.97)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from benchmark_module import benchmark
from insitu.sim.rig import default_rig
from insitu.sim.world import sim_world

SEED = 0


def _draws(k: int, n: int = 64) -> np.ndarray:
    """The first ``n`` normal draws of the renderer of variation ``k`` of :data:`SEED`
    (its speckle field, frame offsets, blotches and sensor noise all come from this stream)."""
    ep = benchmark("engrave_plate")
    rig = default_rig(seed=SEED)
    world = sim_world("blank-stainless", seed=SEED,
                      rig=replace(rig, optics=replace(rig.optics, **ep.VARIATIONS[k][2])))
    ep.own_draws(world, SEED, k)
    return world.renderer().rng.standard_normal(n)


def test_each_variation_of_a_seed_draws_its_own_random_numbers():
    draws = np.array([_draws(k) for k in range(len(benchmark("engrave_plate").VARIATIONS))])
    r = np.corrcoef(draws)[np.triu_indices(len(draws), 1)]
    assert np.abs(r).max() < 0.6, r
    assert np.array_equal(_draws(1), draws[1])


def test_the_lines_along_y_are_the_first_pass():
    """A crossed plan's lines (the crossed pass, at 45°, numbered first by :func:`line_ids`),
    points along each: :func:`line_passes` gives the lines along y as pass 1, the crossed
    ones as pass 2; a plain scan's lines: one pass."""
    from insitu.marking.engrave_passes import line_passes
    from insitu.reconstruct.packing import line_ids
    from insitu.services.scan import plan_lines

    region = (-10.5, 10.5, -2.5, 2.5)
    for cross in (True, False):
        lines = plan_lines(region, 0.1, cross=cross)
        ids = np.array(line_ids(lines))
        t = np.linspace(0, 1, 40)[:, None]
        xy = np.vstack([a[:2] + t * (b - a)[:2] for a, b in lines])
        line = np.repeat(ids, len(t))
        vertical = np.array([abs((b - a)[0]) < 1e-9 for a, b in lines])
        passes = line_passes(xy, line)
        assert len(passes) == (2 if cross else 1)
        assert np.array_equal(np.sort(passes[0].lines), np.sort(ids[vertical]))
        if cross:
            assert np.array_equal(np.sort(passes[1].lines), np.sort(ids[~vertical]))


def test_the_passes_combine_by_their_variances():
    """Two passes 2 and 4 µm off with σ 2 and 4 µm, SHARED_MM of each common to both: the
    means weighted by the rest of their variances, SHARED_MM kept whole in the σ; not stated
    when a pass has too few lines or 2σ exceeds the tolerance; one pass: itself."""
    from insitu.marking.engrave_stats import SHARED_MM

    combined = benchmark("engrave_plate").combined
    mean, sem, ok = combined([(0.002, 0.002, True), (0.004, 0.004, True)])
    w = 1 / np.array([4e-6 - SHARED_MM ** 2, 16e-6 - SHARED_MM ** 2])
    assert np.isclose(mean, (0.002 * w[0] + 0.004 * w[1]) / w.sum())
    assert np.isclose(sem, np.sqrt(1 / w.sum() + SHARED_MM ** 2)) and 0.0018 < sem < 0.002
    assert ok
    assert not combined([(0.002, 0.002, True), (0.004, 0.004, False)])[2]
    assert not combined([(0.002, 0.004, True), (0.002, 0.004, True)])[2]
    assert np.allclose(combined([(0.002, 0.002, True)])[:2], (0.002, 0.002))


def test_the_plate_keeps_its_2_mm_pockets_and_spaces_wider_ones():
    """2 mm pockets at x = −7.5, −2.5, 2.5, 7.5 (the plate every spent seed was run on); 6 mm
    ones 9 mm apart, each one's top ring (1.5 mm) clear of the next pocket, on a 40 mm blank."""
    ep = benchmark("engrave_plate")
    assert np.allclose(ep.centres_x(2.0), [-7.5, -2.5, 2.5, 7.5])
    c = ep.centres_x(6.0)
    assert np.all(np.diff(c) - 6.0 >= 2 * 1.5) and c.max() + 3.0 + 2 < 20.0
