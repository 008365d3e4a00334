"""A stripe running along the edge between a black and a white square for longer than the
course window (benchmarks/clipped_white.py, tune seed 11: a red line clipped white on the white
squares, red on the black ones, 8.5 px halo): the white square's bright side pulls a method's
centre onto the edge, where the stripe's colour lies on one side only (course.on_laser drops
it), and the gap is filled from the laser colour's excess, also where the laser's channel
clips (course.fill_gaps)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from insitu.vision.centres import photo_centres

_PATH = Path(__file__).parents[2] / "benchmarks" / "clipped_white.py"


def _clipped_white():
    spec = importlib.util.spec_from_file_location("clipped_white", _PATH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_stripe_along_a_white_squares_edge_is_found_and_not_pulled_onto_it():
    cw = _clipped_white()
    bgr, true, _ = cw.photograph(11)
    c = photo_centres(bgr, "gaussian")
    board = np.isfinite(true)
    err = np.full(true.shape, np.nan)
    u = np.round(c.u).astype(int)
    err[u] = c.v - true[u]
    err = err[board]
    right = np.abs(np.nan_to_num(err, nan=99.0)) <= cw.WRONG_PX
    wrong = np.isfinite(err) & ~right
    assert right.mean() >= 0.9
    assert wrong.mean() <= 0.005
