"""The compiled passes give what the array forms they replace give: the band search
(vision.detect_kernel; the array form vision.peak_rows: each column's first greatest pixel in
its band, and the greatest more than w rows from it, on frames with bands that end inside the
±w rows), the frame's noise, the wander's correlation length, each column's FWHM and
clipping, the chains' junctions, the smoothing's runs and kept points, Steger's derivatives,
the band's rows and rectangle (their array forms here)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view
from scipy.signal import savgol_filter

from insitu.vision.chains import OWN_COLUMNS, junction
from insitu.vision.detect_kernel import band_peaks
from insitu.vision.extract import CROP_MARGIN, _run_edges, _wander, band_crop
from insitu.vision.peak_rows import band_rows, peak_rows, second_rows
from insitu.vision.profile import frame_noise, fwhm, gather
from insitu.vision.smooth_kernel import kept_and_smoothed, local_quadratic
from insitu.vision.steger import _kernels
from insitu.vision.steger_kernel import column_derivatives, widths_and_clipping


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


def _noise_array_form(img):
    """frame_noise's array form: the sampled rows' 3-row strips median-filtered by OpenCV,
    their differences 8 rows apart at every second column, the median of their size."""
    H = img.shape[0]
    d = min(8, H - 1)
    idx = np.arange(0, H - d, max(1, (H - d) // 32))
    rows = np.r_[idx, idx + d]
    strips = np.ascontiguousarray(img[np.clip(rows[:, None] + np.arange(-1, 2), 0, H - 1)
                                      .ravel()])
    pre = cv2.medianBlur(strips, 3)[1::3].astype(np.float64)
    diff = np.abs(pre[:len(idx), ::2] - pre[len(idx):, ::2])
    return float(1.4826 / np.sqrt(2.0) * np.median(diff))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_frame_noise_equals_the_array_form(dtype):
    rng = np.random.default_rng(5)
    for k in range(60):
        H, W = int(rng.integers(2, 90)), int(rng.integers(1, 70))
        top = int(rng.integers(2, 4096 if dtype != np.uint8 else 256))
        img = rng.integers(0, top, (H, W) if k % 4 else (W, H)).astype(dtype)
        img = img if k % 4 else img.T                              # a transposed view
        assert frame_noise(img) == _noise_array_form(img), (k, img.shape)


def _wander_array_form(v, edges, min_run=80, max_lag=24):
    """_wander's array form: each long run's residual about scipy's Savitzky–Golay
    quadratic, laid end to end with zeros between, correlated by one product."""
    parts = [np.zeros(max_lag)]
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a >= min_run:
            r = v[a:b] - savgol_filter(v[a:b], 61 if b - a > 61 else min_run - 1, 2)
            parts += [r - r.mean(), np.zeros(max_lag)]
    if len(parts) == 1:
        return 0.0
    flat = np.concatenate(parts)
    acf = sliding_window_view(flat, max_lag + 1).T @ flat[:len(flat) - max_lag]
    rho = acf / acf[0]
    end = np.argmax(rho[1:] <= 0) + 1 if (rho[1:] <= 0).any() else len(rho)
    return float(1.0 + 2.0 * rho[1:end].sum())


def test_wander_equals_the_array_form():
    rng = np.random.default_rng(6)
    for _ in range(80):
        n = int(rng.integers(60, 1500))
        v = np.cumsum(rng.normal(size=n)) * 0.05 + np.convolve(rng.normal(size=n + 4),
                                                                np.ones(5) / 5, "valid")
        edges = np.unique(np.r_[0, rng.integers(0, n, rng.integers(0, 8)), n])
        assert abs(_wander(v, edges) - _wander_array_form(v, edges)) < 1e-9


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_widths_and_clipping_equal_the_array_form(dtype):
    rng = np.random.default_rng(7)
    H, W, w = 60, 400, 9
    img = rng.integers(0, 120, (H, W)).astype(dtype)
    r = rng.integers(-3, H + 3, W)                       # peaks by the frame's edges too
    c = np.arange(W)
    img[np.clip(r, 0, H - 1), c] = np.where(c % 2, 255, 200)     # clipped in every 2nd
    img[np.clip(r[::3] + 1, 0, H - 1), c[::3]] = 200
    img[np.clip(r[::4] + 2, 0, H - 1), c[::4]] = 255              # clipped 2 rows below
    pre = cv2.medianBlur(img, 3)
    gmax = pre[np.clip(r, 0, H - 1), c].astype(np.float64)
    half = (gmax - rng.uniform(0, 150, W) + gmax) / 2
    width, sat = widths_and_clipping(pre, img, r, c, w, half, np.float32(250))
    g, inside = gather(pre, r[None, :] + np.arange(-w, w + 1)[:, None], c)
    assert np.array_equal(width, fwhm(g, inside, 2 * half - gmax, gmax))
    near = gather(img, r[None, :] + np.arange(-2, 3)[:, None], c)[0].max(axis=0) >= 250
    assert near.any() and not near.all() and np.array_equal(sat, near)


def _junction_array_form(lab1, lab2, own1, own2):
    W = len(lab1)
    cols = np.arange(W)
    lo, hi, n = np.full(2 * W, W), np.full(2 * W, -1), np.zeros(2 * W, int)
    for lab, own in ((lab1, own1), (lab2, own2)):
        np.minimum.at(lo, lab[own], cols[own])
        np.maximum.at(hi, lab[own], cols[own])
        np.add.at(n, lab[own], 1)
    a, b = lab1, lab2
    line = (n[a] >= OWN_COLUMNS) & (n[b] >= OWN_COLUMNS)
    return line & (((hi[a] < cols) & (lo[b] > cols)) | ((hi[b] < cols) & (lo[a] > cols)))


def test_junction_equals_the_array_form():
    rng = np.random.default_rng(8)
    hits = 0
    for _ in range(40):
        W = int(rng.integers(20, 300))
        lab1 = np.sort(rng.integers(0, 6, W))                # chains along the columns
        lab2 = np.sort(rng.integers(6, 12, W))[::-1].copy()
        own1, own2 = rng.random(W) < 0.6, rng.random(W) < 0.6
        want = _junction_array_form(lab1, lab2, own1, own2)
        assert np.array_equal(junction(lab1, lab2, own1, own2), want)
        hits += want.sum()
    assert hits


def _jumps_array_form(u, v, jump_px):
    du, dv = np.diff(u), np.diff(v)
    near = (du > 0.5) & (du < 1.5)
    slope = np.median(dv[near] / du[near]) if near.any() else 0.0
    return np.abs(dv - slope * du) > jump_px


def _smooth_array_form(u, v, peak, h, jump_px, end_fraction, drop_short=3):
    """smooth_centres' array form on centres sorted by u: the runs, each run's kept points,
    the stretches and each point's quadratic (local_quadratic, the kernel already held to
    its array form by the smoothing's tests)."""
    edges = np.r_[0, np.flatnonzero((np.diff(u) > 1.5) | _jumps_array_form(u, v, jump_px))
                  + 1, len(u)]
    level = 0.0
    if end_fraction > 0:
        level = np.repeat([end_fraction * np.median(peak[a:b]) for a, b in
                           zip(edges[:-1], edges[1:])], np.diff(edges))
    at = np.arange(len(u))
    bright = peak >= level
    first = np.minimum.reduceat(np.where(bright, at, len(u)), edges[:-1])
    last = np.maximum.reduceat(np.where(bright, at, -1), edges[:-1])
    piece = np.repeat(np.arange(len(first)), np.diff(edges))
    keep = ((at >= first[piece]) & (at <= last[piece])
            & (last - first + 1 >= drop_short)[piece])
    col, kv = np.round(u[keep]).astype(np.int64), v[keep]
    if len(kv) < 2:
        return edges, keep, kv
    cut = (np.diff(col) > h + 1) | _jumps_array_form(col, kv, jump_px)
    a = np.r_[0, np.flatnonzero(cut) + 1]
    return edges, keep, local_quadratic(col, kv, a, np.r_[a[1:], len(kv)] - 1, h)


@pytest.mark.parametrize("end_fraction", [0.0, 0.5])
def test_runs_and_smoothing_equal_the_array_form(end_fraction):
    rng = np.random.default_rng(9)
    for k in range(60):
        n = int(rng.integers(1, 400))
        u = np.cumsum(rng.choice([1.0, 1.0, 1.0, 2.0, 9.0], n)) + rng.normal(0, 0.05, n)
        v = 0.3 * u + rng.normal(0, 0.4, n) + 6.0 * (rng.random(n) < 0.02).cumsum()
        peak = rng.uniform(20, 255, n)
        h = int(rng.integers(2, 12))
        edges, keep, want = _smooth_array_form(u, v, peak, h, 1.0, end_fraction)
        assert np.array_equal(_run_edges(u, v, 1.0), edges)
        got_keep, got = kept_and_smoothed(np.round(u).astype(np.int64), v, peak, edges, h, 1.0,
                                          end_fraction, 3)
        assert np.array_equal(got_keep, keep) and np.array_equal(got, want), k


def _derivatives_array_form(img, r, c, h, M):
    """column_derivatives' array form: each column's patch (rows r − M − R … r + M + R,
    columns c − R … c + R, clipped) as float32, summed along u then v over the kernel in its
    order, one float32 product and sum at a time."""
    H, W = img.shape
    R = h.shape[1] // 2
    out = np.empty((5, 2 * M + 1, len(r)), np.float32)
    for i in range(len(r)):
        rows = np.clip(np.arange(r[i] - M - R, r[i] + M + R + 1), 0, H - 1)
        cols = np.clip(np.arange(c[i] - R, c[i] + R + 1), 0, W - 1)
        patch = img[rows[:, None], cols[None, :]].astype(np.float32)
        A = np.zeros((3, len(rows)), np.float32)
        for q in range(h.shape[1]):
            A = A + patch[:, q] * h[:, q, None]
        for k, (a, b) in enumerate(((1, 0), (0, 1), (2, 0), (0, 2), (1, 1))):
            d = np.zeros(2 * M + 1, np.float32)
            for q in range(h.shape[1]):
                d = d + A[a, q:q + 2 * M + 1] * h[b, q]
            out[k, :, i] = d
    return out


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_column_derivatives_equal_the_array_form(dtype):
    rng = np.random.default_rng(9)
    H, W = 60, 150
    img = rng.integers(0, 4000 if dtype != np.uint8 else 256, (H, W)).astype(dtype)
    n = 140                                           # more than one block, the frame's edges
    r, c = rng.integers(-3, H + 3, n), rng.integers(-3, W + 3, n)
    h = _kernels(1.7, 6)
    got = column_derivatives(img, r, c, h, 4)
    assert np.array_equal(got, _derivatives_array_form(img, r, c, h, 4))


def _band_rows_array_form(shape, band):
    """band_rows' array form: the band's ends rounded inwards, the columns searched where
    they are finite, in order and meet the frame's rows, clipped to them."""
    H, W = shape
    blo, bhi = (np.broadcast_to(np.asarray(b, np.float64), (W,)) for b in band)
    with np.errstate(invalid="ignore"):
        flo, fhi = np.ceil(blo), np.floor(bhi)
        searched = (np.isfinite(flo) & np.isfinite(fhi) & (flo <= fhi) & (flo <= H - 1)
                    & (fhi >= 0))
    lo = np.where(searched, np.clip(flo, 0, H - 1), 0).astype(np.int64)
    hi = np.where(searched, np.clip(fhi, 0, H - 1), -1).astype(np.int64)
    return lo, hi, searched, max(int((hi - lo).max()) if W else 0, 0) + 1


def test_band_rows_equal_the_array_form():
    rng = np.random.default_rng(11)
    for k in range(40):
        H, W = int(rng.integers(1, 200)), int(rng.integers(0, 300))
        lo = rng.uniform(-50, H + 50, W).round(int(rng.integers(0, 3)))
        lo[rng.random(W) < 0.1] = np.nan
        hi = lo + rng.uniform(-5, 120, W)
        hi[rng.random(W) < 0.05] = np.inf
        band = (lo, hi) if k % 5 else (float(rng.uniform(-5, H)), float(rng.uniform(0, H + 5)))
        got, want = band_rows((H, W), band), _band_rows_array_form((H, W), band)
        assert all(np.array_equal(a, b) for a, b in zip(got, want)), k


def _band_crop_array_form(shape, band, margin=CROP_MARGIN):
    """band_crop's array form: the columns whose band is finite, in order and meets the
    frame's rows, their rows' extent and margin round it, clipped to the frame."""
    H, W = shape
    lo, hi = (np.broadcast_to(np.asarray(b, np.float64), (W,)) for b in band)
    with np.errstate(invalid="ignore"):
        cols = np.flatnonzero(np.isfinite(lo) & np.isfinite(hi) & (lo <= hi)
                              & (hi >= 0) & (lo <= H - 1))
    if not len(cols):
        return (slice(0, min(H, 1)), slice(0, min(W, 1))), (lo[:1], hi[:1])
    r0 = int(min(max(np.floor(lo[cols].min()) - margin, 0), H - 1))
    r1 = int(min(max(np.ceil(hi[cols].max()) + margin + 1, r0 + 1), H))
    c0, c1 = max(int(cols[0]) - margin, 0), min(int(cols[-1]) + margin + 1, W)
    return (slice(r0, r1), slice(c0, c1)), (lo[c0:c1] - r0, hi[c0:c1] - r0)


def test_band_crop_equals_the_array_form():
    rng = np.random.default_rng(13)
    for k in range(60):
        H, W = int(rng.integers(1, 400)), int(rng.integers(1, 500))
        lo = rng.uniform(-150, H + 150, W).round(int(rng.integers(0, 3)))
        lo[rng.random(W) < (0.1 if k % 7 else 1.0)] = np.nan
        hi = lo + rng.uniform(-5, 120, W)
        if k % 6 == 0:                                  # a band whose first row is the last
            lo[:], hi[:] = np.nan, np.nan
            lo[W // 2], hi[W // 2] = H - 1, H + 3
        band = (lo, hi) if k % 5 else (float(rng.uniform(-5, H)), float(rng.uniform(0, H + 5)))
        (rows, cols), (blo, bhi) = band_crop((H, W), band)
        (rows_, cols_), (blo_, bhi_) = _band_crop_array_form((H, W), band)
        assert (rows, cols) == (rows_, cols_), k
        assert np.array_equal(blo, blo_, equal_nan=True) and np.array_equal(bhi, bhi_,
                                                                              equal_nan=True)
