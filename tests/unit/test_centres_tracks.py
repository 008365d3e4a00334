"""A stripe is the longest track of ridges, not each scan line's brightest ridge: a red stripe
clipped white on a white board of dark dots (dim red on the dots), beside laser-coloured
clutter (a wicker chair's orange edges against a dark room, each brighter than the stripe on a
dot).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from insitu.vision import tracks
from insitu.vision.centres import CENTRE_METHODS, UncertainLine, photo_centres
from insitu.vision.tracks import track_length

H, W = 360, 720


def dot_board_photo(seed: int = 0):
    """(photo (H, W, 3) uint8 BGR, JPEG-decoded; true stripe row per column (W,), NaN off
    the board)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    board = (xx > 40) & (xx < W - 40) & (yy > 120)
    refl = np.where(board, 0.8, 0.12).astype(np.float32)
    for cx in np.arange(70, W - 60, 48):                       # a row of dark dots
        refl[np.hypot(xx - cx, yy - 250) < 17] = 0.08
    refl = cv2.GaussianBlur(refl, (0, 0), 1.0)
    true = 250 + 0.02 * (np.arange(W) - W / 2)
    stripe = np.exp(-0.5 * ((yy - true[None, :]) / 1.6) ** 2) * 2000 * refl
    halo = cv2.GaussianBlur(stripe, (0, 0), 5.0) * 0.3
    room = 200 * refl
    chair = np.zeros((H, W), np.float32)          # a wicker chair's orange edges, dark room
    for row, (c0, c1) in ((20, (150, 290)), (40, (380, 520))):
        for k in range(3):
            wave = row + 18 * k + 5 * np.sin(xx / (17.0 + 4 * k))
            chair += np.exp(-0.5 * ((yy - wave) / 1.2) ** 2) * ((xx >= c0) & (xx < c1)) * 230
    laser = stripe + halo
    bgr = [0.9 * room + 0.08 * laser + 0.35 * chair, 0.95 * room + 0.1 * laser + 0.6 * chair,
           room + laser + chair]
    bgr = [np.clip(c + rng.normal(0, 1.5, c.shape) + 0.5, 0, 255).astype(np.uint8) for c in bgr]
    ok, jpg = cv2.imencode(".jpg", cv2.merge(bgr), [cv2.IMWRITE_JPEG_QUALITY, 92])
    true[:60] = true[W - 60:] = np.nan
    return cv2.imdecode(jpg, cv2.IMREAD_COLOR), true


@pytest.mark.parametrize("method", list(CENTRE_METHODS))
def test_the_stripe_dim_on_dark_dots_beats_brighter_laser_coloured_clutter(method):
    bgr, true = dot_board_photo()
    c = photo_centres(bgr, method)
    err = np.full(W, np.nan)
    err[np.round(c.u).astype(int)] = c.v - true[np.round(c.u).astype(int)]
    on = np.isfinite(true)
    got = on & np.isfinite(err)
    right = got & (np.abs(np.nan_to_num(err)) <= 5)
    assert right.sum() >= 0.95 * on.sum(), right.sum() / on.sum()
    assert (got & ~right).sum() <= 0.01 * on.sum(), (got & ~right).sum() / on.sum()


def test_a_track_goes_on_across_a_gap_where_it_keeps_its_course():
    """Candidates (k=2, W=200): a sloping line lost for 40 columns, and a flat piece of 60
    columns inside that span; the line's two pieces are one track of 160 columns, the flat
    piece one of 60; a piece that resumes 30 px off the line's course is a track of its own."""
    cols = np.arange(200)
    row = np.zeros((2, 200))
    ok = np.zeros((2, 200), bool)
    row[0] = 100 + 0.5 * cols
    ok[0] = (cols < 80) | (cols >= 120)
    row[1, 50:110], ok[1, 50:110] = 20, True
    length = track_length(row, ok, 4.0)
    assert (length[0][ok[0]] == 160).all() and (length[1][ok[1]] == 60).all()
    row[0, 120:] += 30
    length = track_length(row, ok, 4.0)
    assert (length[0, :80] == 80).all() and (length[0, 120:] == 80).all()


def mirrored_photo(seed: int = 0):
    """(photo (H, W, 3) uint8 BGR, JPEG-decoded; the stripe's row (W,)): a red stripe on a
    board, lost on five dark squares (340 of its 640 columns lit), and its dimmer reflection
    in a glossy floor below, unbroken over 460 columns: the longer track."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    true = 150 + 0.02 * (np.arange(W) - W / 2)
    lit = (xx >= 40) & (xx < 680) & ~((xx >= 120) & (xx < 660) & ((xx - 120) % 120 < 60))
    stripe = np.exp(-0.5 * ((yy - true[None, :]) / 1.6) ** 2) * 900 * lit
    mirror = np.exp(-0.5 * ((yy - (460 - true[None, :])) / 2.0) ** 2) * 110 \
        * ((xx >= 100) & (xx < 560))
    room = np.where(yy < 230, 150, 30).astype(np.float32)
    laser = stripe + mirror
    bgr = [room + 0.08 * laser, room + 0.1 * laser, room + laser]
    bgr = [np.clip(c + rng.normal(0, 1.5, c.shape) + 0.5, 0, 255).astype(np.uint8) for c in bgr]
    ok, jpg = cv2.imencode(".jpg", cv2.merge(bgr), [cv2.IMWRITE_JPEG_QUALITY, 92])
    return cv2.imdecode(jpg, cv2.IMREAD_COLOR), true


def test_a_longer_reflection_beside_a_broken_stripe_is_refused(monkeypatch):
    """The reflection is the longest track; the stripe's pieces beside it span more columns
    than it holds: which is the stripe cannot be told, and photo_centres says so rather than
    give the reflection's centres (which it gives when any rival is let pass)."""
    bgr, true = mirrored_photo()
    with pytest.raises(UncertainLine, match=r"rows 3\d\d–3\d\d and 1\d\d–1\d\d.*--background"):
        photo_centres(bgr, "steger")
    monkeypatch.setattr(tracks, "RIVAL", np.inf)
    c = photo_centres(bgr, "steger")
    assert np.median(c.v - true[np.round(c.u).astype(int)]) > 100
