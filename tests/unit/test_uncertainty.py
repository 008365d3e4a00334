"""The σ of a located pose (:mod:`insitu.locate.uncertainty`): points on one edge that share
an error — a bias along a whole edge, a drift along it — are not independent; the σ that
counts them as such is too small, the one of segments and per-edge biases holds."""

from dataclasses import replace

import numpy as np
import pytest

from insitu.geometry.pose import pose_matrix
from insitu.locate.uncertainty import (
    FRAME_TILT_PX,
    LOCK_PX,
    FitTerms,
    covariance,
    edges_of,
    frame_tilt,
    rim_moved,
    rim_sigma,
    segments_of,
)

HALF = 10.0                      # a 20 × 20 mm square part, its four edges
RIM = np.array([[-HALF, -HALF], [HALF, -HALF], [HALF, HALF], [-HALF, HALF]])


def square(spacing=0.05):
    """(points (K, 2), outward normals (K, 2), edge index (K,)) along the square's edges."""
    s = np.arange(-HALF + 1, HALF - 1, spacing)
    pts, nrm, edge = [], [], []
    for k, (n, along) in enumerate((((1, 0), (0, 1)), ((-1, 0), (0, 1)), ((0, 1), (1, 0)),
                                    ((0, -1), (1, 0)))):
        n, along = np.array(n, float), np.array(along, float)
        pts.append(HALF * n + s[:, None] * along)
        nrm.append(np.tile(n, (len(s), 1)))
        edge.append(np.full(len(s), k))
    return np.vstack(pts), np.vstack(nrm), np.concatenate(edge)


def fit(residuals, xy, n):
    """Least squares of the turn (about the origin) and shift on distances across the edges:
    (the pose error (turn rad, x, y), FitTerms)."""
    J = np.column_stack([n[:, 1] * xy[:, 0] - n[:, 0] * xy[:, 1], n])
    x = np.linalg.lstsq(J, residuals, rcond=None)[0]
    r = residuals - J @ x
    spread = 1.4826 * np.median(np.abs(r - np.median(r)))
    return x, FitTerms(J, np.ones(len(r)), r, xy, n, np.full(len(r), 5.0), np.ones(len(r)),
                       spread)


def independent(t):
    """The covariance that takes every point as independent: spread² · A⁻¹."""
    return t.spread_mm ** 2 * np.linalg.inv(t.J.T @ (t.J * t.w[:, None]))


def test_the_edges_and_segments_of_a_square():
    xy, n, edge = square()
    got = edges_of(xy, n, np.full(len(xy), 5.0))
    assert len(np.unique(got)) == 4
    for k in range(4):                                   # each true edge is one found edge
        assert len(np.unique(got[edge == k])) == 1
    seg = segments_of(xy, got, 3.0)
    assert len(np.unique(seg)) == 4 * 6                  # 18 mm an edge, 3 mm a segment


def test_rim_sigma_of_a_shift_and_a_turn():
    cov = np.diag([0.0, 0.01 ** 2, 0.02 ** 2])
    assert np.isclose(rim_sigma(cov, RIM), 0.02)
    turn = np.diag([np.radians(0.1) ** 2, 0.0, 0.0])
    assert np.isclose(rim_sigma(turn, RIM), np.radians(0.1) * HALF * np.sqrt(2))
    assert np.isclose(rim_moved(RIM, pose_matrix(0, 0, 0), pose_matrix(0.03, 0, 0)), 0.03)


def test_a_bias_along_each_edge_is_counted():
    """Each edge's points off by their own bias (0.03 mm, as a lit wall moves a grey step)
    and white noise: σ from independent points is 1/√N small and the shift lies far
    beyond 3 of it; with the per-edge bias in the model, within 3σ in 95 trials of 100 (a
    shift in the plane: a 2-D Gaussian lies beyond 3σ 1 % of the time)."""
    xy, n, edge = square()
    rng = np.random.default_rng(3)
    naive, honest = [], []
    shift = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    for _ in range(100):
        r = rng.normal(0, 0.03, 4)[edge] + rng.normal(0, 0.02, len(xy))
        x, terms = fit(r, xy, n)
        err = np.hypot(*x[1:])
        naive.append(err / np.sqrt(np.linalg.eigvalsh(shift @ independent(terms) @ shift.T)
                                   .max()))
        honest.append(err / np.sqrt(np.linalg.eigvalsh(shift @ covariance(terms, 0.03)
                                                       @ shift.T).max()))
    assert np.mean(np.array(naive) > 3) > 0.5
    assert np.mean(np.array(honest) > 3) <= 0.05


def test_an_error_that_wanders_along_an_edge_shows_in_its_segments():
    """An error correlated over ~1 mm along each edge (pixel quantisation drifting as an edge
    crosses the pixel grid) and no bias prior: the segments' spread sees it, the independent
    points' does not."""
    xy, n, edge = square()
    rng = np.random.default_rng(5)
    kernel = np.exp(-0.5 * (np.arange(-60, 61) * 0.05 / 0.5) ** 2)
    naive, robust = [], []
    for _ in range(100):
        wander = np.convolve(rng.normal(0, 1, len(xy) + 120), kernel, "valid")
        r = 0.02 * wander / wander.std() + rng.normal(0, 0.01, len(xy))
        x, terms = fit(r, xy, n)
        err = rim_moved(RIM, pose_matrix(*x[1:], np.degrees(x[0])), pose_matrix(0, 0, 0))
        naive.append(err / rim_sigma(independent(terms), RIM))
        robust.append(err / rim_sigma(covariance(terms, 0.0), RIM))
    assert np.mean(np.array(naive) > 3) > 0.3
    assert np.mean(np.array(robust) > 3) <= 0.05


def test_an_edge_turned_by_its_bias_is_counted():
    """Each edge's error growing along it (± 0.03 mm at its ends, drawn per edge): the turn
    it gives is within 3σ with the per-edge term, not without it."""
    xy, n, edge = square()
    rng = np.random.default_rng(7)
    t = np.where(np.abs(n[:, 0]) > 0.5, xy[:, 1], xy[:, 0]) / (HALF - 1)
    naive, honest = [], []
    for _ in range(100):
        r = rng.normal(0, 0.03, 4)[edge] * t + rng.normal(0, 0.02, len(xy))
        x, terms = fit(r, xy, n)
        naive.append(abs(x[0]) / np.sqrt(independent(terms)[0, 0]))
        honest.append(abs(x[0]) / np.sqrt(covariance(terms, 0.03)[0, 0]))
    assert np.mean(np.array(naive) > 3) > 0.3
    assert np.mean(np.array(honest) > 3) <= 0.05


def test_a_frame_edge_along_a_pixel_row_may_turn_one_across_rows_hardly():
    """The pull of an edge's grey step toward the pixel grid turns an edge that stays within
    a pixel of one row end to end (LOCK_PX at its ends); one crossing 40 rows averages it out
    to the light's FRAME_TILT_PX; the turn's σ follows."""
    xy, n, edge = square()
    z = np.full(len(xy), 5.0)
    px = 0.16                                           # mm a pixel
    level = xy / px
    tilted = level @ np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]]).T
    along_rows = frame_tilt(xy, n, z, level)
    across = frame_tilt(xy, n, z, tilted)
    assert np.allclose(along_rows, np.hypot(FRAME_TILT_PX, LOCK_PX))
    assert np.all(across < 1.1 * FRAME_TILT_PX)
    rng = np.random.default_rng(1)
    _, terms = fit(rng.normal(0, 0.01, len(xy)), xy, n)
    sigma = [np.sqrt(covariance(replace(terms, along=np.full(len(xy), px), tilt=t), 0.1)[0, 0])
             for t in (along_rows, across)]
    assert sigma[0] > 3 * sigma[1]


def test_a_reference_piece_left_unchecked_counts_more_than_a_checked_one():
    """Each point's own reference σ (a scan reference's pieces: those its crossed scan checks
    0.03 mm, the others 0.1): all alike, the same covariance as one σ for all; one side
    unchecked, a larger σ across it than the checked sides give."""
    xy, n, edge = square()
    _, terms = fit(np.random.default_rng(2).normal(0, 0.01, len(xy)), xy, n)
    same = covariance(replace(terms, reference=np.full(len(xy), 0.03)), 0.0)
    assert np.allclose(same, covariance(terms, 0.0, reference_mm=0.03))
    one = covariance(replace(terms, reference=np.where(edge == 0, 0.1, 0.03)), 0.0)
    assert one[1, 1] > 2 * same[1, 1] and np.isclose(one[2, 2], same[2, 2], rtol=0.2)


def test_a_piece_fitted_to_line_ends_is_held_to_their_bias_not_to_their_scatter():
    """A scan reference's piece fitted to its crossed scan's line ends (where its frame shows
    no edge) scatters 0.08 mm rms by the lines' spacing: 1σ 0.04 mm across, 0.03 of its turn
    (their bias on the corpus' references); a frame's piece scattering so (a weak grey step)
    keeps its floor grown with the scatter, 0.4 mm."""
    from insitu.locate.uncertainty import LINE_ENDS_MM, reference_floor

    assert reference_floor(0.08, False, "scan") == LINE_ENDS_MM == (0.04, 0.03)
    assert reference_floor(0.08, False) == pytest.approx((0.4, 0.4))
    assert reference_floor(0.08, False, "frame")[0] > 5 * LINE_ENDS_MM[0]


def test_two_independent_turns_are_joined_only_against_a_mesh_and_when_they_agree():
    """The scan's turn (1σ 0.04°) and the frame's (0.03°) of one part against a mesh: joined
    by their inverse variances (0.024°), turned about the top's centre (which stays); against
    a scan reference (whose outline both share), or 2σ apart, the pose is left as it was."""
    from types import SimpleNamespace

    from insitu.geometry.pose import pose_matrix
    from insitu.locate.search import Solution, joined_turn

    centre = np.array([3.0, -2.0])
    ref = SimpleNamespace(kind="mesh", top_centroid=centre)
    sol = Solution(10.0, 5.0, 0.0, 30.0, 1.0, 1.0, 0.01, edges=100, sigma_deg=0.04)
    got = joined_turn(ref, sol, 30.05, 0.03)
    assert np.isclose(got.angle_deg, 30.0 + 0.05 * 0.04 ** 2 / (0.04 ** 2 + 0.03 ** 2))
    assert np.isclose(got.sigma_deg, 0.024) and np.isclose(got.turn_sigma_deg, 0.024)
    stays = [(pose_matrix(o.x_mm, o.y_mm, o.angle_deg) @ [*centre, 0, 1])[:2] for o in (sol, got)]
    assert np.allclose(*stays, atol=1e-9)
    assert joined_turn(SimpleNamespace(kind="cloud", top_centroid=centre), sol, 30.05, 0.03) is sol
    assert joined_turn(ref, sol, 30.11, 0.03) is sol                   # 2.2σ apart
    assert joined_turn(ref, sol, 30.05, None) is sol
