"""A red stripe whose core clips white in all three channels, with a red halo, across a bright
dot board (its white face unclipped), in a room with a lamp that clips white, a red glint (the
laser reflected by a shiny part) and the edge of a white cupboard; sensor noise, JPEG with
chroma at half resolution. Drawn in numpy (fast), with the proportions of the full-HD set of
benchmarks/real_sets.py (zhaocongyang/structured_LineLight_calib) at half size.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from insitu.vision.centres import CENTRE_METHODS, UncertainLine, photo_centres
from naive_centre import naive_com

H, W = 540, 960
BOARD = (200, 760, 80, 500)                      # x0, x1, y0, y1 px: the board's white face
ON = slice(210, 750)                             # the columns scored
LAMP, GLINT = (120, 160), (600, 420)             # centres px
CUPBOARD = 830                                   # its edge, px


def clipped_photo(seed: int = 0, halo: float = 5.0, floor: float = 0.0, board: float = 215.0):
    """(H, W, 3) uint8 BGR JPEG-decoded photograph and the stripe's true row per column (W,);
    halo: its sigma, px (the reach the laser colour is looked for in is 5 px here); floor:
    the peak of the stripe's reflection in a glossy floor under the board (row 520, columns
    300–700; 0: none); board: its white face's gray value."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    room = 120.0 + 0.05 * xx                                           # a wall, lit unevenly
    x0, x1, y0, y1 = BOARD
    room[(xx > x0) & (xx < x1) & (yy > y0) & (yy < y1)] = board
    for cx in range(260, 740, 80):
        for cy in range(130, 480, 80):
            room[(xx - cx) ** 2 + (yy - cy) ** 2 < 18 ** 2] = 35.0     # the dots
    room[xx >= CUPBOARD] = 235.0
    room = cv2.GaussianBlur(room, (0, 0), 1.0)
    true = 300.0 + 0.1 * (np.arange(W) - 480)
    d = yy - true[None, :]
    light = (2400 * np.exp(-0.5 * (d / 1.6) ** 2) + 260 * np.exp(-0.5 * (d / halo) ** 2)) \
        * np.clip(room / 215.0, 0.1, 1.1)                               # core, halo × albedo
    light += 900 * np.exp(-((xx - GLINT[0]) ** 2 + (yy - GLINT[1]) ** 2) / (2 * 9.0 ** 2))
    light += floor * np.exp(-0.5 * ((yy - 520) / 2.5) ** 2) * ((xx > 300) & (xx < 700))
    lamp = (xx - LAMP[0]) ** 2 + (yy - LAMP[1]) ** 2 < 40 ** 2
    raw = []
    for c in (0.86 * room + 0.05 * light, 0.93 * room + 0.08 * light, room + light):  # B, G, R
        c = np.where(lamp, 400.0, c)
        noisy = c + rng.normal(0, 1.0, c.shape) * np.sqrt(np.maximum(c, 0) / 6 + 2)
        raw.append(np.clip(noisy + 0.5, 0, 255).astype(np.uint8))
    ok, jpg = cv2.imencode(".jpg", cv2.merge(raw), [cv2.IMWRITE_JPEG_QUALITY, 90])
    return cv2.imdecode(jpg, cv2.IMREAD_COLOR), true


@pytest.fixture(scope="module")
def photo():
    return clipped_photo()


def errors(c, true) -> np.ndarray:
    """(W,) the centre's error per column, px (NaN: none)."""
    err = np.full(W, np.nan)
    u = np.round(c.u).astype(int)
    err[u] = c.v - true[u]
    return err


@pytest.mark.parametrize("method", list(CENTRE_METHODS))
def test_a_clipped_white_core_with_a_halo_is_the_stripe(photo, method):
    """Found on ≥ 90 % of the board's columns, ≤ 1 % wrong (> 5 px), at most 0.9 × the RMS
    error of a naive centre of mass of the red channel on the columns both found."""
    bgr, true = photo
    check(bgr, true, photo_centres(bgr, method))


@pytest.mark.parametrize("method", ["gray", "gaussian", "steger"])
def test_a_halo_wider_than_the_reach(method):
    """A halo of sigma 8 px, wider than the 5 px reach: the white core is still allowed
    (its flanks' laser colour from a top-hat 3 × wider), and the line's colour is weighed
    on that wider top-hat too (not refused). Steger drops the columns on the dots' rims,
    where the stripe is no ridge: it finds less, never a wrong centre."""
    bgr, true = clipped_photo(0, halo=8.0)
    check(bgr, true, photo_centres(bgr, method), found=0.85 if method == "steger" else 0.9)


def test_the_stripes_reflection_in_a_glossy_floor_is_neither_stripe_nor_fringe():
    """A reflection of the stripe in a glossy floor, a long laser-coloured ridge under 400 of
    the board's 540 columns: the stripe is the longer track, and the reflection, a ridge of
    the laser's own channel, is no colour fringe (the photograph is measured, not
    refused)."""
    bgr, true = clipped_photo(1, floor=1500.0)
    c = photo_centres(bgr, "gray")
    check(bgr, true, c)
    assert not (np.abs(c.v - 520) < 20).any()


def check(bgr, true, c, found: float = 0.9) -> None:
    err = errors(c, true)[ON]
    right = np.abs(np.nan_to_num(err, nan=99)) <= 5
    assert right.mean() >= found and (np.isfinite(err) & ~right).mean() <= 0.01
    naive = (naive_com(bgr[:, :, 2]) - true)[ON]
    both = right & (np.abs(naive) <= 5)
    rms, rms_naive = (float(np.sqrt(np.mean(e[both] ** 2))) for e in (err, naive))
    assert rms <= 0.9 * rms_naive, (rms, rms_naive)


@pytest.mark.parametrize("method", list(CENTRE_METHODS))
def test_the_lamp_the_glint_and_the_cupboards_edge_get_no_centre(photo, method):
    """No centre on the lamp (clipped white, no laser colour), on the red glint (laser
    colour, but a blob: no ridge along the scan lines) or on the cupboard's edge (an edge of
    a bright object, no ridge); beyond the board, on the wall and the cupboard the stripe
    still lights, every centre lies on the stripe."""
    bgr, true = photo
    c = photo_centres(bgr, method)
    for x, y in (LAMP, GLINT):
        assert not (np.hypot(c.u - x, c.v - y) < 30).any(), (x, y)
    off_board = (c.u < BOARD[0]) | (c.u > BOARD[1])
    assert (np.abs(errors(c, true)[np.round(c.u[off_board]).astype(int)]) <= 5).all()
    assert off_board.sum() > 0.5 * (W - (BOARD[1] - BOARD[0]))


def test_the_red_channel_alone_loses_it(photo):
    """What the sum of the channels does: in the red channel (``--channel r``) the halo
    clips as the core does; the stripe is found on far fewer columns, or the photograph is
    refused (its centres carry no more laser colour than the edges' fringes)."""
    bgr, true = photo
    try:
        err = errors(photo_centres(bgr, "gray", channel="r"), true)[ON]
    except UncertainLine:
        return
    assert (np.abs(np.nan_to_num(err, nan=99)) <= 5).mean() < 0.6


def test_a_white_run_counts_only_with_laser_colour_on_both_sides_and_when_short():
    """laser_image._flanked on one row, reach 2: a 3 px white run with laser colour 2 px
    before it and 3 px after it (within reach + 1) counts; one with it on one side only, or 9 px
    long (> 4 reach: a lamp), does not."""
    from insitu.vision.laser_image import _flanked

    laser = np.zeros((3, 30), bool)
    white = np.zeros((3, 30), bool)
    laser[0, [3, 10]], white[0, 5:8] = True, True                 # flanked
    laser[1, 3], white[1, 5:8] = True, True                       # one side only
    laser[2, [3, 16]], white[2, 5:14] = True, True                # too long
    out = _flanked(laser, white, 2)
    assert out[0, 5:8].all() and out[0].sum() == 3
    assert not out[1].any() and not out[2].any()


@pytest.mark.parametrize("method", list(CENTRE_METHODS))
def test_a_halo_clipped_wide_in_the_red_channel_is_measured_in_the_sum(method):
    """On a brighter board (235) a halo of sigma 10 px clips the red channel over a plateau
    some 30 px wide: there the red channel holds no ridge, and its own centres go to the
    stripe's weak, thin, unclipped reflection in the floor (row 520). The sum of the channels
    holds the stripe as a ridge whose red channel is clipped: the photograph is measured in
    the sum, on the stripe (not refused for the colour of the reflection's centres). The
    halo nearly clips green too: on the white face the core stands some 50 gray values over
    its sides in the sum, from blue alone, and is found there (≥ 58 % of the columns; the
    rest are the dots' rims)."""
    bgr, true = clipped_photo(1, halo=10.0, floor=60.0, board=235.0)
    c = photo_centres(bgr, method)
    err = errors(c, true)[ON]
    right = np.abs(np.nan_to_num(err, nan=99)) <= 5
    assert right.mean() >= 0.58 and (np.isfinite(err) & ~right).mean() <= 0.01
    assert not (np.abs(c.v - 520) < 20).any()


@pytest.mark.parametrize("method", ["gaussian", "steger"])
def test_a_wide_white_core_under_jpeg_is_centred_on_its_plateau(method):
    """A green stripe clipped white over about 10 px (core sigma 2.4 px, 4500 gray values at
    its peak, a 10 px halo) on a bright board, JPEG at quality 90: JPEG rings the clipped
    plateau a few gray values below full scale, and those pixels count as clipped
    (centres.CLIPPED); fitted as flanks they put the centre up to 5 px off its middle."""
    rng = np.random.default_rng(1)
    yy = np.mgrid[0:H, 0:W][0].astype(np.float32)
    true = 300.0 + 0.1 * (np.arange(W) - 480)
    d = yy - true[None, :]
    light = 4500 * np.exp(-0.5 * (d / 2.4) ** 2) + 340 * np.exp(-0.5 * (d / 10) ** 2)
    raw = []
    for c in (0.86 * 215 + 0.1 * light, 0.93 * 215 + light, 215 + 0.25 * light):   # B, G, R
        noisy = c + rng.normal(0, 1.0, c.shape) * np.sqrt(np.maximum(c, 0) / 6 + 2)
        raw.append(np.clip(noisy + 0.5, 0, 255).astype(np.uint8))
    ok, jpg = cv2.imencode(".jpg", cv2.merge(raw), [cv2.IMWRITE_JPEG_QUALITY, 90])
    err = errors(photo_centres(cv2.imdecode(jpg, cv2.IMREAD_COLOR), method), true)[100:860]
    assert np.isfinite(err).mean() >= 0.85 and np.nanmax(np.abs(err)) <= 2.0


@pytest.mark.parametrize("method", list(CENTRE_METHODS))
def test_a_core_standing_out_in_blue_alone_above_a_halo_clipping_red_and_green(method):
    """A red stripe with a strong 17 px halo on a bright board: red is clipped some 20 px
    either side of the line, green over the core and its flanks, and the core (white) stands
    some 40 gray values over its sides in blue alone. Two clipped channels carry no noise, so
    in the sum the core is held to blue's noise floor (detect's ``quiet``); held to the three
    channels' floor, it is found on a third of the columns."""
    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    room = np.where((xx > 100) & (xx < 860) & (yy > 60) & (yy < 480), 200.0, 120.0)
    true = 300.0 + 0.1 * (np.arange(W) - 480)
    d = yy - true[None, :]
    light = (3700 * np.exp(-0.5 * (d / 1.9) ** 2) + 400 * np.exp(-0.5 * (d / 17) ** 2)) \
        * room / 200
    raw = []
    for c in (0.86 * room + 0.11 * light, 0.93 * room + 0.18 * light, room + light):  # B, G, R
        noisy = c + rng.normal(0, 1.5, c.shape) * np.sqrt(np.maximum(c, 0) / 6 + 2)
        raw.append(np.clip(noisy + 0.5, 0, 255).astype(np.uint8))
    ok, jpg = cv2.imencode(".jpg", cv2.merge(raw), [cv2.IMWRITE_JPEG_QUALITY, 90])
    err = errors(photo_centres(cv2.imdecode(jpg, cv2.IMREAD_COLOR), method), true)[110:850]
    right = np.abs(np.nan_to_num(err, nan=99)) <= 5
    assert right.mean() >= 0.9 and (np.isfinite(err) & ~right).mean() <= 0.01
