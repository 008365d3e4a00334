"""The scan's banded extraction (insitu.vision.extract.extract_centres with a band): only the
band's rectangle is read, and the centres are those of the whole frame searched in the band."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.special import ndtr

from insitu.formats.sequence import Sequence
from insitu.reconstruct.plane import band_and_side, line_runs_along_rows
from insitu.services.common import camera_model
from insitu.vision.extract import CentreSettings, band_crop, extract_centres
from insitu.vision.laser_image import noise_sigma, read_window
from insitu.vision.profile import frame_noise

SCAN = Path(__file__).resolve().parents[1] / "data" / "scan-step-block-b2"


def assert_same(a, b, tol=0.01):
    """Same columns, centres within ``tol`` px, the same peaks, widths and contrasts (what the
    extraction read about each line: its background too)."""
    assert len(a) > 0 and np.array_equal(np.round(a.u), np.round(b.u))
    assert np.abs(a.u - b.u).max() <= tol and np.abs(a.v - b.v).max() <= tol
    for f in ("peak", "width", "contrast", "saturated"):
        np.testing.assert_allclose(getattr(a, f), getattr(b, f), atol=1e-9, err_msg=f)


def inside(c, lo, hi, along_rows=True):
    """Whether every centre lies in the band (lo, hi) of its scan line."""
    scan, cross = (c.u, c.v) if along_rows else (c.v, c.u)
    k = np.round(scan).astype(int)
    return bool(np.all((cross >= lo[k] - 0.5) & (cross <= hi[k] + 0.5)))


@pytest.mark.parametrize("index", [0, 3, 6])
def test_recorded_frames_banded_equal_whole_frame(index):
    """Frames of the recorded step-block scan (our simulator, binning 2): the band the head's
    focus range allows, read from its rectangle only, gives the whole frame's centres."""
    seq = Sequence.open(SCAN)
    cam, head = camera_model(seq.camera), seq.scan_head
    f = seq.spec.frames[index]
    start, end = np.asarray(f.line.start, float), np.asarray(f.line.end, float)
    rows = line_runs_along_rows(cam, start, end)
    lo, hi, upper = band_and_side(cam, start, end, head.pivot_height_mm,
                                  tuple(head.z_range_mm), along_rows=rows)
    image = seq.read_frame(index)
    (r, c), _ = band_crop(image.shape if rows else image.shape[::-1], (lo, hi))
    assert (r.stop - r.start) * (c.stop - c.start) < 0.6 * image.size   # a part of the frame
    banded = extract_centres(image, CentreSettings(), (lo, hi), rows, upper)
    whole = extract_centres(image, CentreSettings(), (lo, hi), rows, upper, crop=False)
    assert_same(banded, whole)
    assert len(banded) > 200 and inside(banded, lo, hi, rows)


def synthetic(H=600, W=900, seed=0):
    """(H, W) uint8: a line along the rows near row 300 + 0.05·u, a brighter ghost line near
    row 120 and a bright slab at rows 480–560, on noise; and the line's true rows (W,)."""
    rng = np.random.default_rng(seed)
    u = np.arange(W, dtype=np.float64)
    rows = np.arange(H, dtype=np.float64)[:, None]

    def line(v0, amp, sigma=1.6):
        return amp * sigma * np.sqrt(2 * np.pi) * (ndtr((rows + 0.5 - v0) / sigma)
                                                   - ndtr((rows - 0.5 - v0) / sigma))

    true = 300.0 + 0.05 * u + 3 * np.sin(u / 90)
    img = 15 + line(true, 170) + line(120 + 0.02 * u, 240) + rng.normal(0, 2, (H, W))
    img[480:560] += 150
    return np.clip(np.round(img), 0, 255).astype(np.uint8), true


@pytest.mark.parametrize("along_rows", [True, False])
def test_synthetic_banded_equals_whole_frame_and_stays_in_band(along_rows):
    """A ghost brighter than the line and a bright slab lie outside the band, and the line
    near the band's edge (what the centres read about it reaches beyond the band): the banded
    extraction finds the line, never them, with the whole frame's centres — also for a line
    along the columns (the frame transposed)."""
    img, true = synthetic()
    H, W = img.shape
    lo = 300.0 + 0.05 * np.arange(W) - 6                    # the line 3–9 rows inside
    hi = lo + 60
    lo[:60] = hi[:60] = np.nan                                # columns the line cannot reach
    frame = img if along_rows else np.ascontiguousarray(img.T)
    banded = extract_centres(frame, CentreSettings(), (lo, hi), along_rows)
    whole = extract_centres(frame, CentreSettings(), (lo, hi), along_rows, crop=False)
    assert_same(banded, whole)
    assert inside(banded, lo, hi, along_rows)
    scan, cross = (banded.u, banded.v) if along_rows else (banded.v, banded.u)
    assert scan.min() >= 60 and np.abs(cross - true[np.round(scan).astype(int)]).max() < 0.2


@pytest.mark.parametrize("window", [(300, 700, 160, 900), (0, 1000, 48, 400),
                                    (5, 37, 0, 1000), (960, 1000, 961, 1000)])
def test_a_region_of_interests_frame_is_measured_where_it_was_read(window):
    """A camera reading a region of interest gives the whole frame with 0 outside it: the noise
    is the region's, not the zeros' (0 when they are most of the frame), and a frame read whole
    is measured whole even with pixels at 0."""
    rng = np.random.default_rng(4)
    img = np.clip(rng.normal(12.0, 3.0, (1000, 1000)), 0, 255).astype(np.uint8)
    r0, r1, c0, c1 = window
    read = np.zeros_like(img)
    read[r0:r1, c0:c1] = img[r0:r1, c0:c1]
    assert read_window(read).shape == (r1 - r0, c1 - c0)
    assert read_window(read.T).shape == (c1 - c0, r1 - r0)
    assert np.shares_memory(read_window(read), read)
    crop = np.ascontiguousarray(img[r0:r1, c0:c1])
    for frame in (read, read.T):
        assert frame_noise(frame) == frame_noise(crop if frame is read else crop.T) > 1.0
        assert noise_sigma(frame) == noise_sigma(crop if frame is read else crop.T) > 2.0
    assert read_window(img) is img and read_window(img.astype(np.float32)).shape == img.shape


def test_frame_noise_is_the_whole_frames():
    """The noise the crop is measured with is the median-filtered frame's (detect's own)."""
    img, _ = synthetic(seed=3)
    assert frame_noise(img) == pytest.approx(noise_sigma(cv2.medianBlur(img, 3)), abs=1e-12)
    t = img.T
    assert frame_noise(t) == pytest.approx(noise_sigma(cv2.medianBlur(np.ascontiguousarray(t),
                                                                      3)), abs=1e-12)
