"""benchmarks/clipped_white.py scores only the board's columns where the stripe is seen: where
the clipped lamp is drawn over the stripe's true row (spent seed 13005: 88 of the board's 1129
columns) there is nothing to find, and a method is neither credited nor blamed there."""

from __future__ import annotations

import functools

import numpy as np

from benchmark_module import benchmark
from insitu.vision.detect import LineCentres

SEED = 13005


@functools.lru_cache(maxsize=1)
def _photograph():
    return benchmark("clipped_white").photograph(SEED)


def _board_and_course():
    cw = benchmark("clipped_white")
    col = np.arange(cw.W, dtype=np.float32)
    course = cw.stripe_course(cw.settings(SEED), col)
    board = (col > 310) & (col < 1440) & (course > 110) & (course < 850)
    return board, course


def test_the_columns_left_out_are_those_the_lamp_covers_white():
    bgr, true, _ = _photograph()
    board, course = _board_and_course()
    out = board & np.isnan(true)
    assert out.sum() == 88
    assert np.array_equal(true[~out & board], course[~out & board])
    u = np.flatnonzero(out)
    assert bgr[np.round(course[u]).astype(int), u].min() >= 240    # the lamp's white (JPEG)


def test_a_method_right_wherever_the_stripe_is_seen_scores_all_found_none_wrong(monkeypatch):
    cw = benchmark("clipped_white")
    bgr, true, lc = _photograph()
    board, course = _board_and_course()
    u = np.flatnonzero(board).astype(np.float64)
    lx, ly = cw.settings(SEED)["lamp"]
    lamp = (u - lx) ** 2 + (np.round(course[board]) - ly) ** 2 < 45 ** 2    # its radius, px
    v = np.where(lamp, ly, course[board])                # the lamp's middle where it covers
    n = len(u)
    centres = LineCentres(u, v.astype(np.float64), np.full(n, 255.0), np.ones(n), np.ones(n))
    monkeypatch.setattr(cw, "photo_centres", lambda *a, **k: centres)
    found, wrong, _, _ = cw.score(bgr, true, lc, "gray")
    assert found == 1.0 and wrong == 0.0
