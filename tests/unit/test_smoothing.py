"""Smoothing of the line centres along the line (insitu.vision.extract.smooth_centres): a local
quadratic over the window, along stretches that only a discontinuity cuts."""

import numpy as np
from scipy.signal import savgol_filter

from insitu.vision.detect import LineCentres
from insitu.vision.extract import smooth_centres

W = 600


def centres(u, v, peak=None) -> LineCentres:
    u = np.asarray(u, np.float64)
    peak = np.full(len(u), 200.0) if peak is None else peak
    return LineCentres(u, np.asarray(v, np.float64), peak, np.full(len(u), 3.0),
                       np.full(len(u), 180.0))


def true_v(u):
    return 1000.0 + 0.08 * u + 3.0 * np.sin(u / 120.0)


def test_an_unbroken_line_is_savitzky_golay():
    rng = np.random.default_rng(1)
    u = np.arange(W, dtype=np.float64)
    v = true_v(u) + rng.normal(0, 0.1, W)
    out = smooth_centres(centres(u, v), half_window=15)
    np.testing.assert_allclose(out.v, savgol_filter(v, 31, 2, mode="interp"), atol=1e-9)


def test_pieces_between_dark_blotches_are_smoothed():
    """Dark speckle blotches take 3 columns out every 20: each piece is shorter than the
    31-column window. Smoothing that skips pieces shorter than its window leaves them raw
    (error RMS = the 0.15 px noise)."""
    rng = np.random.default_rng(2)
    u = np.arange(W)
    u = u[(u % 20) >= 3].astype(np.float64)
    v = true_v(u) + rng.normal(0, 0.15, len(u))
    out = smooth_centres(centres(u, v), half_window=15)
    assert len(out) == len(u)
    e = out.v - true_v(out.u)
    assert np.sqrt(np.mean(e**2)) < 0.1 and np.abs(e).max() < 0.3


def test_a_spike_is_dropped_and_the_line_runs_on_across_it():
    rng = np.random.default_rng(3)
    u = np.arange(W, dtype=np.float64)
    v = true_v(u) + rng.normal(0, 0.1, W)
    v[300] += 2.5                                     # a column on a ghost or a blotch
    out = smooth_centres(centres(u, v), half_window=15)
    assert 300 not in out.u and len(out) == W - 1
    e = out.v - true_v(out.u)
    assert np.abs(e[(out.u > 285) & (out.u < 315)]).max() < 0.1


def test_a_step_across_a_gap_stays_sharp():
    """A 4 px step (a wall seen end on) with 5 columns lost at it: the two levels are fitted
    apart, each point within 0.15 px of its own level."""
    rng = np.random.default_rng(4)
    u = np.arange(W, dtype=np.float64)
    step = np.where(u >= 300, 4.0, 0.0)
    keep = (u < 298) | (u > 302)
    u, v = u[keep], (true_v(u) + step + rng.normal(0, 0.05, W))[keep]
    out = smooth_centres(centres(u, v), half_window=15)
    e = out.v - true_v(out.u) - np.where(out.u >= 300, 4.0, 0.0)
    assert len(out) == len(u) and np.abs(e).max() < 0.15


def test_a_steep_line_is_kept_whole_and_its_steps_cut():
    """A crossed pass's line climbs 0.85 px a column: speckle's wobble (0.2 px) on top of
    that is no jump — a rule of |Δv| > 1 px would cut it into pieces too short to keep and
    lose a fifth of its centres, its last columns on a top among them. A step of 1.2 px
    against the slope (Δv = −0.35 px) is one."""
    rng = np.random.default_rng(4)
    u = np.arange(200, dtype=np.float64)
    v = 500.0 + 0.85 * u + rng.normal(0, 0.2, len(u))
    out = smooth_centres(centres(u, v), half_window=7)
    assert len(out) == len(u)
    assert np.abs(out.v - (500.0 + 0.85 * u)).max() < 0.3
    stepped = np.where(u < 100, v, v - 1.2)
    out = smooth_centres(centres(u, stepped), half_window=7)
    near = (u >= 97) & (u <= 102)                # the step stays sharp, not smoothed over
    expect = 500.0 + 0.85 * u - np.where(u < 100, 0.0, 1.2)
    assert np.abs(out.v[near] - expect[near]).max() < 0.3
