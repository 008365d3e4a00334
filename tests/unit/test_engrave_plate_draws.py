"""benchmarks/engrave_plate.py: each variation of a seed draws its own speckle and noise, so a
seed's eight rows are eight independent results (from one stream, the read noise × 3 row would
be the base row's draws scaled: their flat top's residuals correlate 0.97)."""

from __future__ import annotations

import functools
import importlib.util
from dataclasses import replace
from pathlib import Path

import numpy as np

from insitu.sim.rig import default_rig
from insitu.sim.world import sim_world

_PATH = Path(__file__).parents[2] / "benchmarks" / "engrave_plate.py"
SEED = 0


@functools.lru_cache(maxsize=1)
def _plate():
    spec = importlib.util.spec_from_file_location("engrave_plate", _PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _draws(k: int, n: int = 64) -> np.ndarray:
    """The first ``n`` normal draws of the renderer of variation ``k`` of :data:`SEED`
    (its speckle field, frame offsets, blotches and sensor noise all come from this stream)."""
    ep = _plate()
    rig = default_rig(seed=SEED)
    world = sim_world("blank-stainless", seed=SEED,
                      rig=replace(rig, optics=replace(rig.optics, **ep.VARIATIONS[k][2])))
    ep.own_draws(world, SEED, k)
    return world.renderer().rng.standard_normal(n)


def test_each_variation_of_a_seed_draws_its_own_random_numbers():
    draws = np.array([_draws(k) for k in range(len(_plate().VARIATIONS))])
    r = np.corrcoef(draws)[np.triu_indices(len(draws), 1)]
    assert np.abs(r).max() < 0.6, r
    assert np.array_equal(_draws(1), draws[1])
