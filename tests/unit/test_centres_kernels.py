"""The compiled passes give what the array forms they replace give: the band search
(vision.detect_kernel; the array form vision.peak_rows: each column's first greatest pixel in
its band, and the greatest more than w rows from it, on frames with bands that end inside the
±w rows), the frame's noise, the wander's correlation length, each column's FWHM and
clipping, the chains' junctions, the smoothing's runs and kept points, Steger's derivatives
and centres, a clipped plateau's flank fit, the band's rows and rectangle (their array forms
here)."""

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
from insitu.vision.steger_kernel import (
    clipped_centres,
    column_derivatives,
    plateau_centres,
    steger_columns,
    widths_and_clipping,
)


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


def _hermite_array_form(y0, d0, y1, d1):
    """_hermite_root's array form (float32): Newton from the linear estimate, 4 steps."""
    f = np.float32
    s = np.clip(y0 / np.where(y0 != y1, y0 - y1, f(1)), f(0), f(1))
    a2 = f(3) * (y1 - y0) - f(2) * d0 - d1
    a3 = f(2) * (y0 - y1) + d0 + d1
    for _ in range(4):
        p = y0 + s * (d0 + s * (a2 + s * a3))
        dp = d0 + s * (f(2) * a2 + s * (f(3) * a3))
        s = np.clip(s - p / np.where(np.abs(dp) > f(1e-12), dp, f(1e-12)), f(0), f(1))
    return s


def _steger_array_form(img, r, c, h, M, min_curvature, across):
    """steger_columns' array form: the Hessian's eigenvalues, normal and Taylor step at every
    row of every column (float32, numpy's steps), the strongest passing row (rows 1 … 2M −
    1; the first row where none passes), the column alone where none does (``across``), the
    root of n·∇I by the cubic Hermite fit with the next or the previous row."""
    f, k2, n = np.float32, 2 * M + 1, len(r)
    Iu, Iv, Iuu, Ivv, Iuv = column_derivatives(img, r, c, h, M)
    half, d = (Iuu + Ivv) / f(2), (Iuu - Ivv) / f(2)
    root = np.sqrt(d * d + Iuv * Iuv)
    lam, other = half - root, half + root
    e1v, e2u = lam - Iuu, lam - Ivv
    first = Iuv * Iuv + e1v * e1v >= e2u * e2u + Iuv * Iuv
    a, b = np.where(first, Iuv, e2u), np.where(first, e1v, Iuv)
    norm = np.hypot(a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        tiny = norm < f(1e-12)
        a, b = np.where(tiny, f(0), a / norm), np.where(tiny, f(1), b / norm)
        t = -(a * Iu + b * Iv) / lam
        t1 = -Iv / Ivv
    inner = (np.arange(k2) > 0)[:, None] & (np.arange(k2) < k2 - 1)[:, None]
    ok = (inner & (lam <= -min_curvature) & (-lam >= np.abs(other))
          & (np.abs(t * a) <= f(0.6)) & (np.abs(t * b) <= f(0.6)))
    cols = np.arange(n)
    k = np.argmax(np.where(ok, -lam, -np.inf), axis=0)
    hit = ok.any(axis=0)
    bu, bv, bt = a[k, cols], b[k, cols], t[k, cols]
    ok1 = inner & (Ivv <= -min_curvature) & (np.abs(t1) <= f(0.6))
    k1 = np.argmax(np.where(ok1, -Ivv, -np.inf), axis=0)
    alone = across & ~hit & ok1.any(axis=0)
    k = np.where(alone, k1, k)
    bu, bv = np.where(alone, f(0), bu), np.where(alone, f(1), bv)
    bt, hit = np.where(alone, t1[k1, cols], bt), hit | alone
    g, dg = bu * Iu + bv * Iv, bu * Iuv + bv * Ivv
    y0, d0 = g[k, cols], dg[k, cols]
    yn, dn = g[(k + 1) % k2, cols], dg[(k + 1) % k2, cols]
    yp, dp = g[(k - 1) % k2, cols], dg[(k - 1) % k2, cols]
    with np.errstate(divide="ignore", invalid="ignore"):
        down = np.sign(y0) != np.sign(yn)
        root = down | (np.sign(yp) != np.sign(y0))
        s = np.where(down, _hermite_array_form(y0, d0, yn, dn),
                     _hermite_array_form(yp, dp, y0, d0))
    u = np.where(root, c, c + (bt * bu).astype(np.float64))
    v = r + (k - M) + np.where(root, s.astype(np.float64) - np.where(down, 0.0, 1.0),
                               (bt * bv).astype(np.float64))
    return u, v, hit


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_steger_columns_equal_the_array_form(dtype):
    rng = np.random.default_rng(17)
    H, W, n = 70, 260, 250
    x = np.arange(W)
    line = 30 + 8 * np.sin(x / 25) + np.where(x > 130, 9, 0)          # a step
    sigma = np.where(x % 3, 1.6, 2.4)
    img = 20 + 180 * np.exp(-0.5 * ((np.arange(H)[:, None] - line) / sigma) ** 2)
    img[:, 200:215] += 90 * np.exp(-0.5 * ((np.arange(H)[:, None] - line[200:215]) / 7) ** 2)
    img = np.clip(img + rng.normal(0, 6, (H, W)), 0, 255).astype(dtype)
    c = rng.integers(-3, W + 3, n)                            # the frame's edges too
    r = np.round(line[np.clip(c, 0, W - 1)]).astype(np.int64) + rng.integers(-3, 4, n)
    r[::17] = rng.integers(-3, H + 3, len(r[::17]))           # off the line
    h = _kernels(1.7, 6)
    for across in (True, False):
        u, v, found = steger_columns(img, r, c, h, 4, np.float32(2.0), across)
        u_, v_, found_ = _steger_array_form(img, r, c, h, 4, np.float32(2.0), across)
        assert found.any() and not found.all() and np.array_equal(found, found_)
        assert np.array_equal(u, u_, equal_nan=True) and np.array_equal(v, v_, equal_nan=True)


def _segment_array_form(mask, at):
    """(k, n) bool: the run of True rows of ``mask`` (k, n) holding row ``at`` (n,)."""
    label, cols = np.cumsum(~mask, axis=0), np.arange(mask.shape[1])
    return mask & (label == label[at, cols]) & mask[at, cols]


def _run_centroid_array_form(raw, inside, sat, bg, g):
    """_run_centroid's array form: the centroid above half-way (or, on a steep background,
    above the mean of the peak and the higher side 3 px beyond the clipped run) of the
    pixels joined to the peak (the first greatest of the middle rows −2 … +2)."""
    K, n = raw.shape
    h, cols = K // 2, np.arange(n)
    peak = h - 2 + np.argmax(raw[h - 2:h + 3], axis=0)
    run = _segment_array_form(sat, peak)
    first = np.where(run.any(axis=0), np.argmax(run, axis=0), 0)
    last = np.where(run.any(axis=0), K - 1 - np.argmax(run[::-1], axis=0), K - 1)
    lo, hi = np.clip(first - 3, 0, K - 1), np.clip(last + 3, 0, K - 1)
    top = raw[peak, cols]
    steep = np.abs(bg[-1] - bg[0]) > (top - np.maximum(bg[0], bg[-1])) / 2
    level = np.where(steep, ((top + np.maximum(raw[lo, cols], raw[hi, cols])) / np.float32(2))
                     .astype(np.float64), bg + g.max(axis=0) / 2)
    near = _segment_array_form((inside & (raw > level)) | run, peak)
    moment, total = np.zeros(n), np.zeros(n)
    for y in range(K):
        weight = np.where(near[y], raw[y].astype(np.float64) - level[y], 0.0)
        moment, total = moment + weight * (y - h), total + weight
    return moment / np.maximum(total, 1e-9)


def _plateau_array_form(raw, inside, sat, noise, unit):
    """plateau_centres' array form: the sloping background, every row's test (at the floor,
    falling away from the middle or clipped), the rows joined to the middle, their weighted
    moments summed row by row, the log-parabola's vertex; else the run's centroid."""
    f, (K, n) = np.float32, raw.shape
    h, y = K // 2, np.arange(K)[:, None]
    top, bot = (np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))
                for a, b, c in (raw[:3], raw[-3:]))
    mid, slope = (top + bot) / f(2), (bot - top) / f(2 * h)
    bg = mid.astype(np.float64) + slope.astype(np.float64) * (y - h)
    g = np.where(inside, raw.astype(np.float64) - bg, 0.0)
    high = inside & (g >= np.maximum(max(3 * unit, 3 * noise), np.abs(bg[-1] - bg[0])))
    falls = np.ones((K, n), bool)
    falls[:h], falls[h + 1:] = g[:h] <= g[1:h + 1], g[h + 1:] <= g[h:-1]
    above = high & (falls | sat)
    joined = np.zeros((K, n), bool)
    joined[h::-1] = np.logical_and.accumulate(above[h::-1], axis=0)
    joined[h:] = np.logical_and.accumulate(above[h:], axis=0)
    use = high & ~sat & joined
    m, t = np.zeros((5, n)), np.zeros((3, n))
    for row in range(K):
        wgt, x, p = g[row], np.float64(row - h), 1.0
        ly = np.log(np.maximum(wgt, unit))
        for q in range(5):
            m[q] = np.where(use[row], m[q] + p * wgt, m[q])
            if q < 3:
                t[q] = np.where(use[row], t[q] + p * (wgt * ly), t[q])
            p *= x
    c0, c1, c2 = m[2] * m[4] - m[3] ** 2, m[2] * m[3] - m[1] * m[4], m[1] * m[3] - m[2] ** 2
    c3, c4, c5 = m[0] * m[4] - m[2] ** 2, m[1] * m[2] - m[0] * m[3], m[0] * m[2] - m[1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        det = m[0] * c0 + m[1] * c1 + m[2] * c2
        b = (c1 * t[0] + c3 * t[1] + c4 * t[2]) / det
        a = (c2 * t[0] + c4 * t[1] + c5 * t[2]) / det
        vertex = -b / (2 * a)
    fit = ((use & (y < h)).any(axis=0) & (use & (y > h)).any(axis=0) & (use.sum(axis=0) >= 3)
           & (np.abs(det) > 1e-9 * np.maximum(m[0], 1.0) ** 3) & (a < 0)
           & (np.abs(vertex) <= h))
    return np.where(fit, vertex, _run_centroid_array_form(raw, inside, sat, bg, g))


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_clipped_plateaus_equal_the_array_form(dtype):
    rng = np.random.default_rng(19)
    H, W, w = 50, 300, 11
    x = np.arange(W)
    line = np.where(x < 260, 25 + 6 * np.sin(x / 30), 6.0)         # by the frame's edge too
    ys = np.arange(H)[:, None]
    cut = np.where(x % 9 == 0, ys < line + 3, np.where(x % 9 == 4, ys > line - 3, True))
    core = 600 * np.exp(-0.5 * ((ys - line) / 2.5) ** 2) * cut
    img = (30 + 0.8 * ys * (x % 5 == 0) + 120 * (ys > line + 4) * (x % 7 == 0)  # slopes, lit
           + np.where(x % 11 == 0, 0, core) + rng.normal(0, 4, (H, W)))      # side, cut core
    img = np.where(x % 3 == 0, np.round(img / 16) * 16, img)            # ties on the flanks
    img = np.clip(img, 0, 255).astype(dtype)
    r = np.round(line).astype(np.int64) + rng.integers(-2, 3, W)
    level = np.float32(250)
    raw, inside = gather(img, r[None, :] + np.arange(-w, w + 1)[:, None], x)
    want = _plateau_array_form(raw, inside, raw >= level, 2.0, 1.0)
    got = plateau_centres(raw, inside, raw >= level, 2.0, 1.0)
    assert np.array_equal(got, want, equal_nan=True)
    assert np.array_equal(clipped_centres(img, r, x, w, level, 2.0, 1.0), want, equal_nan=True)
