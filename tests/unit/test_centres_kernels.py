"""The compiled band search (vision.detect_kernel) finds the rows the array form
(vision.peak_rows) finds: each column's first greatest pixel in its band, and the greatest
more than w rows from it, on frames with bands that end inside the ±w rows."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from insitu.vision.detect_kernel import band_peaks
from insitu.vision.peak_rows import band_rows, peak_rows, second_rows


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_band_search_equals_the_array_form(dtype):
    rng = np.random.default_rng(3)
    H, W, w = 90, 300, 12
    pre = rng.integers(0, 60, (H, W)).astype(dtype)
    pre[rng.integers(0, H, W), np.arange(W)] = 200                 # a peak, ties beside it
    pre[np.clip(rng.integers(0, H, W) + 1, 0, H - 1), np.arange(W)] = 200
    lo = rng.uniform(-5, 60, W)
    band = (np.where(np.arange(W) % 17 == 0, np.nan, lo), lo + rng.uniform(-2, 40, W))
    first, last, searched, _ = band_rows(pre.shape, band)
    fill = 0 if dtype != np.float32 else -np.inf
    search = cv2.transpose(pre).copy()
    rows = np.arange(H)
    search[~((rows >= first[:, None]) & (rows <= last[:, None]))] = fill
    j1, second = band_peaks(pre, first, last, searched, fill)
    assert np.array_equal(j1, peak_rows(search, first, fill))
    live = searched & (rng.random(W) < 0.8)
    j2, found = second(j1, w, live, 40.0)
    j2_, found_ = second_rows(search, j1, first, fill, w, live, 40.0)
    assert found.any() and np.array_equal(found, found_) and np.array_equal(j2, j2_)
