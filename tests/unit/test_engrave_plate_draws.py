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


def test_the_lines_along_y_are_told_apart_by_their_ids():
    """A crossed scan's points on its lines along y: the ids :func:`line_ids` gives those
    lines (the crossed pass, at 45°, is numbered first); a plain scan's: all."""
    from insitu.reconstruct.packing import line_ids
    from insitu.services.scan import plan_lines

    ep = benchmark("engrave_plate")
    region = (-10.5, 10.5, -2.5, 2.5)
    lines = plan_lines(region, 0.1, cross=True)
    ids = np.array(line_ids(lines))
    vertical = np.array([abs((b - a)[0]) < 1e-9 for a, b in lines])
    assert 0 < vertical.sum() < len(lines)
    line = np.repeat(ids, 3)
    assert np.array_equal(ep.along_y(line, region, 0.1, True), np.repeat(vertical, 3))
    assert ep.along_y(np.arange(211), region, 0.1, False).all()


def test_the_passes_combine_by_their_variances():
    """Two passes 2 and 4 µm off with σ 2 and 4 µm: the combined mean 2.4 µm, σ 1.79 µm; not
    stated when a pass has too few lines or 2σ exceeds the tolerance."""
    combine = benchmark("engrave_plate").combine
    mean, sem, ok = combine([(0.002, 0.002, True), (0.004, 0.004, True)])
    assert np.isclose(mean, 0.0024) and np.isclose(sem, 1 / np.sqrt(1 / 4e-6 + 1 / 16e-6))
    assert ok
    assert not combine([(0.002, 0.002, True), (0.004, 0.004, False)])[2]
    assert not combine([(0.002, 0.004, True), (0.002, 0.004, True)])[2]
    assert combine([(0.002, 0.002, True)]) == (0.002, 0.002, True)


def test_the_plate_keeps_its_2_mm_pockets_and_spaces_wider_ones():
    """2 mm pockets at x = −7.5, −2.5, 2.5, 7.5 (the plate every spent seed was run on); 6 mm
    ones 9 mm apart, each one's top ring (1.5 mm) clear of the next pocket, on a 40 mm blank."""
    ep = benchmark("engrave_plate")
    assert np.allclose(ep.centres_x(2.0), [-7.5, -2.5, 2.5, 7.5])
    c = ep.centres_x(6.0)
    assert np.all(np.diff(c) - 6.0 >= 2 * 1.5) and c.max() + 3.0 + 2 < 20.0
