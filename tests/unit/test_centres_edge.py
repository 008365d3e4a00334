"""A green stripe running along the edge between a row of dark squares and a row of light ones
of a neutral (gray) checkerboard, as a hand-held board puts it (hjamal3/Light-Stripe-Calibration):
in the laser's channel the stripe sits on a step of the board and has no peak of its own over
half of its length; in the channel's excess over the others the gray board cancels and the
stripe is a ridge all along. Optics blur, sensor noise, green crosstalk into red and blue,
JPEG with chroma at half resolution."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from insitu.vision.centres import CENTRE_METHODS, photo_centres
from naive_centre import naive_com

H, W, SQUARE = 480, 640, 80
ON = slice(80, 560)                                    # columns scored (the stripe: 60 … 579)


def edge_photo(seed: int = 0):
    """(H, W, 3) uint8 BGR JPEG-decoded photograph and the stripe's true row per column (W,)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    dark = ((xx // SQUARE).astype(int) + ((yy - 240) // SQUARE).astype(int)) % 2 == 1
    board = cv2.GaussianBlur(np.where(dark, 70.0, 150.0).astype(np.float32), (0, 0), 1.2)
    true = 240.0 + 0.004 * (np.arange(W) - 320)
    line = 70.0 * np.exp(-0.5 * ((yy - true[None, :]) / 1.3) ** 2)
    line[:, :60] = line[:, 580:] = 0
    chans = (0.95 * board + 0.18 * line, board + line, 0.9 * board + 0.15 * line)   # B, G, R
    raw = [np.clip(c + rng.normal(0, 1.5, c.shape) + 0.5, 0, 255).astype(np.uint8)
           for c in chans]
    ok, jpg = cv2.imencode(".jpg", cv2.merge(raw), [cv2.IMWRITE_JPEG_QUALITY, 90])
    return cv2.imdecode(jpg, cv2.IMREAD_COLOR), true


@pytest.fixture(scope="module")
def photo():
    return edge_photo()


def score(c, true):
    """found, wrong (fractions of the scored columns) and the errors (W,) px (NaN: none or
    wrong, or not scored)."""
    err = np.full(W, np.nan)
    u = np.round(c.u).astype(int)
    err[u] = c.v - true[u]
    err[:ON.start] = err[ON.stop:] = np.nan
    right = np.abs(np.nan_to_num(err, nan=99)) <= 5
    n = ON.stop - ON.start
    return right.sum() / n, (np.isfinite(err) & ~right).sum() / n, np.where(right, err, np.nan)


@pytest.mark.parametrize("method", list(CENTRE_METHODS))
def test_a_stripe_along_a_squares_edge_is_found_from_its_colour(photo, method):
    """Found on ≥ 95 % of the columns, none wrong, at most 0.9 × the RMS error of a naive
    centre of mass of the green channel on the columns both found (the step pulls that one
    by px), and within 1 px RMS."""
    bgr, true = photo
    found, wrong, err = score(photo_centres(bgr, method), true)
    assert found >= 0.95 and wrong == 0, (found, wrong)
    naive = naive_com(bgr[:, :, 1]) - true
    both = np.isfinite(err) & (np.abs(naive) <= 5)
    rms, rms_naive = (float(np.sqrt(np.mean(e[both] ** 2))) for e in (err, naive))
    assert both.sum() > 0.9 * (ON.stop - ON.start)
    assert rms <= 0.9 * rms_naive and rms < 1.0, (rms, rms_naive)


def test_the_laser_channel_alone_loses_it_on_the_edges(photo):
    """What the colour does: the green channel forced (``--channel g``) loses the stripe
    where it runs along the dark squares' edges."""
    bgr, true = photo
    found, wrong, _ = score(photo_centres(bgr, "gray", channel="g"), true)
    assert found < 0.9 and wrong == 0, (found, wrong)
