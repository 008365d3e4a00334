"""A photograph's stripe keeps its course across the scan lines: centres that slide off it (onto
the rim of a dark dot, along a bright square's edge) are dropped, a step in depth is kept, and
between the ends of the stripe's track no other track's candidate is taken for it."""

from __future__ import annotations

import functools

import numpy as np

from insitu.vision.course import FILL_PX, in_frame, off_the_excess, on_course, on_laser
from insitu.vision.detect import LineCentres
from insitu.vision.excess_fill import fill_gaps, filled_cores
from insitu.vision.tracks import on_longest_track, track_length


def centres(u, v) -> LineCentres:
    n = len(u)
    return LineCentres(np.asarray(u, float), np.asarray(v, float), np.full(n, 200.0),
                       np.full(n, 3.0), np.full(n, 100.0), np.zeros(n, bool),
                       np.zeros(n, bool), 255.0)


def test_a_stretch_slid_off_the_course_goes_a_step_in_depth_stays():
    """A line v = 300 + 0.1 u over 600 columns: columns 200–239 slide 1 → 8 px off (joined to
    the line, a rim), columns 400–599 are 40 px lower (a step in depth); half span 60."""
    u = np.arange(600.0)
    v = 300 + 0.1 * u
    v[200:240] += np.linspace(1, 8, 40)
    v[400:] += 40
    kept = on_course(centres(u, v), True, 60.0)
    slid = (kept.u >= 200) & (kept.u < 240)
    off = np.abs(kept.v - (300 + 0.1 * kept.u + 40 * (kept.u >= 400))) > FILL_PX
    assert not off.any() and slid.sum() < 25
    assert ((kept.u >= 400).sum() >= 195) and ((kept.u < 200).sum() >= 195)


def test_a_short_piece_between_two_that_run_on_straight_goes_unless_on_their_line():
    """A 30-column piece 12 px off a straight line running on either side of it is dropped;
    the same piece on the line is kept; a short piece past the line's end (no neighbours on
    one side) is kept. The same by rows (a line running down the columns)."""
    u = np.r_[np.arange(100.0), np.arange(110.0, 140.0), np.arange(150.0, 250.0)]
    v = 200 + 0.2 * u
    for off, n_kept in ((12.0, 200), (0.0, 230)):
        w = v.copy()
        w[100:130] += off
        assert len(on_course(centres(u, w), True, 60.0)) == n_kept
        assert len(on_course(centres(w, u), False, 60.0)) == n_kept
    tail = np.r_[np.arange(100.0), np.arange(110.0, 130.0)]
    w = 200 + 0.2 * tail
    w[100:] += 30
    assert len(on_course(centres(tail, w), True, 60.0)) == 120



def test_the_first_piece_past_a_step_stays_when_it_runs_on_into_its_own_side():
    """A wall (columns 0–299) and a board 8 px lower (columns 300–359, a dark mark at
    360–417 with one stray centre 10 px off at its rim, then columns 418–800), all on a line
    of slope −0.05; half span 64: the board's first piece, short, continues the board's
    centres past the mark and stays (a line fitted through the wall and the few board
    columns within 64 of the piece runs along the wall); the stray centre goes. The same
    piece 8 px off the board's line on either side goes."""
    u = np.r_[np.arange(361.0), np.arange(418.0, 801.0)]
    v = 400 - 0.05 * u + 8 * (u >= 300)
    v[360] -= 10
    kept = on_course(centres(u, v), True, 64.0)
    assert len(kept) == len(u) - 1 and 360 not in kept.u
    assert len(on_course(centres(v, u), False, 64.0)) == len(u) - 1
    w = v.copy()
    w[300:360] += 8
    kept = on_course(centres(u, w), True, 64.0)
    assert len(kept) >= len(u) - 61 and not ((kept.u >= 300) & (kept.u < 360)).any()

def fields(row, ok):
    k, W = row.shape
    contrast = np.where(ok, 50.0, 0.0)
    return (row, np.full((k, W), 200.0), np.zeros((k, W)), contrast, ok,
            np.ones((k, W), np.int64))


def test_between_the_stripes_ends_no_other_track_stands_in_for_it():
    """The stripe (row 100, 300 columns, lost at columns 120–159) and its reflection (row 250,
    columns 60–219, 160 columns): the stripe's pieces are one track of 260 columns; in its gap
    the reflection is the only candidate, and no column there gets one."""
    W = 300
    cols = np.arange(W)
    row = np.zeros((2, W))
    ok = np.zeros((2, W), bool)
    row[0], ok[0] = 100.0, (cols < 120) | (cols >= 160)
    row[1], ok[1] = 250.0, (cols >= 60) & (cols < 220)
    assert track_length(row, ok, 4.0)[0, 0] == 260
    chosen_row, *_, valid, _run, _amb = on_longest_track(fields(row, ok), 4.0)
    assert not valid[120:160].any()
    assert valid[:120].all() and valid[160:].all() and (chosen_row[valid] == 100).all()


def test_past_the_stripes_end_its_reflection_stands_not_in_for_it():
    """The stripe (row 100, columns 0–259, lost past them on dark squares) and its reflection
    in a glossy floor (row 490, columns 60–279): the reflection runs mostly beside the stripe,
    so the columns past the stripe's end get no centre from it; a piece of the stripe past
    its end on another track (row 140, columns 280–299: a wall beside the board) stays."""
    W = 300
    cols = np.arange(W)
    row = np.zeros((3, W))
    ok = np.zeros((3, W), bool)
    row[0], ok[0] = 100.0, cols < 260
    row[1], ok[1] = 490.0, (cols >= 60) & (cols < 280)
    row[2], ok[2] = 140.0, cols >= 280
    chosen_row, *_, valid, _run, _amb = on_longest_track(fields(row, ok), 4.0)
    assert (chosen_row[valid] != 490).all()
    assert valid[:260].all() and not valid[260:280].any() and valid[280:].all()


def test_a_track_whose_end_slid_still_bridges_by_its_course():
    """A piece whose last 10 columns slide 8 px off (onto an edge) still joins the piece
    that resumes on its course 20 columns later: its course, not its end row, is carried
    across the gap."""
    W = 300
    cols = np.arange(W, dtype=float)
    row = np.full((1, W), 100.0)
    row[0, 90:100] += np.linspace(1, 8, 10)
    ok = ((cols < 100) | (cols >= 120))[None, :]
    assert track_length(row, ok, 4.0)[0, 0] == 280


def _edge_photo(H: int = 60, W: int = 40, edge: int = 34):
    """(H, W, 3) uint8 BGR: a black square above row ``edge``, a white one from it, and a red
    stripe at row 30 (σ 2 px) whose halo lifts the red channel of both; its core on the black
    square is red, not white."""
    rows = np.arange(H, dtype=np.float32)[:, None]
    ambient = np.where(rows < edge, 35.0, 190.0) * np.ones((1, W), np.float32)
    laser = 600.0 * np.exp(-0.5 * ((rows - 30) / 2.0) ** 2) \
        + 60.0 * np.exp(-0.5 * ((rows - 30) / 8.0) ** 2)
    bgr = np.stack([ambient + 0.08 * laser, ambient + 0.12 * laser, ambient + laser], axis=2)
    return np.clip(bgr, 0, 255).astype(np.uint8)


def test_a_centre_pulled_onto_a_white_squares_edge_has_laser_colour_on_one_side_only():
    """The stripe's centres at row 30 stay; centres on the white square's side of the edge
    (rows 36–40, the neutral step a method's centre is pulled onto) go: below them the white
    square carries no laser colour. A core clipped white with a red halo on both sides stays."""
    bgr = _edge_photo()
    u = np.arange(40.0)
    v = np.where(u < 20, 30.0, 36.0 + (u - 20) / 4)
    kept = on_laser(centres(u, v), bgr, 2, 0.85 * 255, True, 11)
    assert np.array_equal(kept.u, u[:20])
    assert np.array_equal(on_laser(centres(v, u), bgr.transpose(1, 0, 2).copy(), 2,
                                   0.85 * 255, False, 11).v, u[:20])
    core = bgr.copy()
    core[29:32] = 255                                          # clipped white, halo around
    assert len(on_laser(centres(u, np.full(40, 30.0)), core, 2, 0.85 * 255, True, 11)) == 40


def test_a_centre_outside_the_frame_is_dropped():
    """A flank fit with no curvature put one centre 5·10⁹ px off: it goes, as does one left
    of the first column; the others stay."""
    u = np.arange(100.0)
    v = 50 + 0.1 * u
    v[40] = 5e9
    u2 = u.copy()
    u2[0] = -0.6
    kept = in_frame(centres(u2, v), (120, 100))
    assert len(kept) == 98 and kept.v.max() < 120 and kept.u.min() >= 0


def test_a_gap_is_not_filled_from_the_flank_of_a_core_clipped_white():
    """A stripe at row 42 up to column 39 (on the wall) and at row 50 from column 60 (on a
    board in front of it), its core clipped white (rows 48–52) over the gap between: the
    laser's excess has a hole there, and the candidates found in it lie on the halo's flank,
    row 43, on columns 40–49 (near the course interpolated across the gap) and amid the white
    core, row 50.5, on columns 52–59: only the latter fill the gap."""
    u = np.r_[np.arange(40.0), np.arange(60.0, 100.0)]
    c = centres(u, np.where(u < 40, 42.0, 50.0))
    e = centres(np.r_[np.arange(40.0, 50.0), np.arange(52.0, 60.0)],
                np.r_[np.full(10, 43.0), np.full(8, 50.5)])
    white = np.zeros((100, 100), bool)
    white[48:53, 40:] = True
    filled = fill_gaps(c, e, True, white, 8)
    assert filled.u[(filled.u >= 40) & (filled.u < 60)].tolist() == list(range(52, 60))
    assert len(fill_gaps(c, e, True, np.zeros_like(white), 8)) == len(c) + 18


def test_a_long_stretch_beside_the_lasers_colour_goes_one_on_it_stays():
    """A stripe v = 300 + 0.05 u over 600 columns whose centres on columns 200–289 (longer
    than the course's half span, 60) lie 7 px beside it, on a bright square's edge lit by the
    halo, while the laser's excess peaks on the line there: they are replaced by the excess's
    centres. Where the excess's centres on those columns lie 7 px off too (the stripe on a
    raised surface, the laser's colour there), the stretch stays; so do 10 columns
    (450–459) beside the excess, fewer than a stripe's least run (20). Rows and columns."""
    u = np.arange(600.0)
    line = 300 + 0.05 * u
    v = line + 7.0 * ((u >= 200) & (u < 290)) + 6.0 * ((u >= 450) & (u < 460))
    white = np.zeros((800, 800), bool)
    for rows in (True, False):
        def flip(c, rows=rows):
            return c if rows else centres(c.v, c.u)
        for e_v, n_off in ((line, 10), (v, 100)):
            fill = functools.partial(_fill, e=flip(centres(u, e_v)), rows=rows, white=white)
            got = flip(off_the_excess(flip(centres(u, v)), rows, 60.0, 20, fill))
            assert len(got) == 600
            assert np.sum(np.abs(got.v - line) > FILL_PX) == n_off


def _fill(c, e, rows, white):
    return fill_gaps(c, e, rows, white, 8)


def test_a_core_clipped_in_the_lasers_channel_peaks_at_its_middle_a_lit_edge_stays():
    """A red stripe at row 20 (σ 3 px, 1000 gray values at its peak, clipped at 255) whose
    light leaks into green and blue (crosstalk 0.11) beside a bright square (rows 0–8: 200
    in all three, red clipped by the halo): the excess R − (G + B) / 2 dips at the core
    between two peaks 3 px either side. Filled, it peaks at row 20; the square's run, with no
    dip, stays as it is; a dip shallower than the least contrast of a peak stays too."""
    row = np.arange(40.0)[:, None] * np.ones((1, 5))
    light = 1000 * np.exp(-0.5 * ((row - 20) / 3) ** 2)
    square = row <= 8
    bgr = np.empty((40, 5, 3))
    bgr[..., 0] = bgr[..., 1] = np.where(square, 200, 40 + 0.11 * light)
    bgr[..., 2] = np.where(square, 255, np.minimum(40 + light, 255))
    bgr = np.round(bgr).astype(np.uint8)
    ex = np.maximum(bgr[..., 2] - (bgr[..., 0] + bgr[..., 1].astype(float)) / 2, 0)
    ex = ex.astype(np.float32)
    assert (np.abs(ex.argmax(axis=0) - 20) >= 2).all()
    filled = filled_cores(ex, bgr, 2, 255.0, {"min_contrast": 20.0}, 1.0)
    assert (filled.argmax(axis=0) == 20).all()
    assert np.array_equal(filled[:9], ex[:9])
    dip = float(ex[14:27].max() - ex[20].min())
    assert np.array_equal(filled_cores(ex, bgr, 2, 255.0, {"min_contrast": dip + 1}, 1.0), ex)


def test_a_fill_with_a_least_run_takes_no_lone_scan_line():
    """Gaps on columns 40–59 and 70–72 of a stripe at row 50, the excess's centres on all of
    the first and on column 70 within FILL_PX of its course: with a least run of 20
    consecutive scan lines the lone column 70 (a glint, a mark's rim) stays empty, the 20
    are filled."""
    u = np.r_[np.arange(40.0), np.arange(60.0, 70.0), np.arange(73.0, 100.0)]
    c = centres(u, np.full(len(u), 50.0))
    e = centres(np.r_[np.arange(40.0, 60.0), 70.0], np.full(21, 51.0))
    white = np.zeros((100, 100), bool)
    filled = fill_gaps(c, e, True, white, 8, 20)
    assert len(filled) == 100 - 3 and 70 not in filled.u
    assert len(fill_gaps(c, e, True, white, 8)) == 100 - 2


def test_a_fill_of_a_whole_gap_as_long_as_the_colours_reach_counts_shorter_than_a_run():
    """Gaps on columns 30–43, 50–52 and 60–79 of a stripe at row 50, the excess's centres
    within FILL_PX of its course on all of the first two and on 60–73 of the third; a least
    run of 20, the colour's reach 8 px: the first gap (14 scan lines, from the stripe's
    centre before to the one after) is filled; the second, shorter than the reach, and the
    14 centres that leave 74–79 open are not (clipped_white spent seed 13005)."""
    u = np.r_[np.arange(30.0), np.arange(44.0, 50.0), np.arange(53.0, 60.0),
              np.arange(80.0, 100.0)]
    c = centres(u, np.full(len(u), 50.0))
    e = centres(np.r_[np.arange(30.0, 44.0), np.arange(50.0, 53.0), np.arange(60.0, 74.0)],
                np.full(31, 51.0))
    filled = fill_gaps(c, e, True, np.zeros((100, 100), bool), 8, 20)
    assert len(filled) == len(c) + 14
    assert set(range(30, 44)) <= set(filled.u.tolist())
    assert 50 not in filled.u and 60 not in filled.u
