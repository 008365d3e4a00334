"""Statistics of a laser line in an image: how much its brightness varies along the line
(speckle), over what length, with what distribution; the background under it and any secondary
line beside it. The same code measures real photographs and the simulator's frames
(``benchmarks/speckle_stats.py``), so the simulator can be set to match the world.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import stats

_TREND_PX = 25.0       # along-line σ of the slow trend divided out (line generator profile, albedo)
_BAND_PX = 60          # half-width searched for a secondary line
_BG_FROM, _BG_TO = 20, 60   # background ring, px from the line centre


@dataclass(frozen=True)
class LineStats:
    """Along-line statistics of one image's laser line.

    n: positions along the line used; cv: std/mean of the detrended integrated cross-profile;
    cv_peak: the same of the peak value; corr_px: 1/e length of its autocorrelation, px;
    gamma_k: maximum-likelihood gamma shape of the detrended intensity; width_px: median σ of
    the cross-profile; saturated: fraction of positions whose peak is ≥ 250 DN; background:
    median level 20–60 px from the line, DN; texture: std of that background about its 8-px
    smoothed self, DN; shading: std/mean of the smoothed background; secondary_p95: 95th
    percentile of the brightest other peak within ±60 px as a fraction of the line's peak;
    secondary_frac: fraction of positions where it exceeds 0.1."""

    n: int
    cv: float
    cv_peak: float
    corr_px: float
    gamma_k: float
    width_px: float
    saturated: float
    background: float
    texture: float
    shading: float
    secondary_p95: float
    secondary_frac: float


def laser_channel(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) float32 laser signal and (H, W) float32 gray of a gray or BGR image. Colour: the
    channel with the most excess over the mean of the other two (a coloured line on a neutral
    scene), as that excess; gray: the image itself for both."""
    if img.ndim == 2:
        g = img.astype(np.float32)
        return g, g
    f = img.astype(np.float32)
    excess = [f[..., c] - (f.sum(-1) - f[..., c]) / 2 for c in range(3)]
    best = int(np.argmax([np.percentile(e, 99.9) for e in excess]))
    return np.maximum(excess[best], 0.0), f[..., best]


def line_stats(img: np.ndarray, along: str | None = None, bright_only: bool = True) -> LineStats:
    """Statistics of the one laser line in ``img`` (H, W) gray or (H, W, 3) BGR.

    along: "u" (the line runs along the image's columns index, one centre per column) or "v";
    None guesses it from the ridge's orientation. bright_only: use only positions where the
    background beside the line is ≥ 70 % of its 95th percentile (white squares of a
    checkerboard, not the black ones)."""
    sig, gray = laser_channel(img)
    raw = img if img.ndim == 2 else img.max(axis=2)
    if along is None:
        along = _direction(sig)
    if along == "v":
        sig, gray, raw = sig.T, gray.T, np.ascontiguousarray(raw.T)
    H, W = sig.shape
    centre = _centre_curve(sig)
    cols = np.arange(W)
    offs = np.arange(-_BAND_PX - _BG_TO, _BAND_PX + _BG_TO + 1)
    rows = np.rint(centre)[None, :].astype(int) + offs[:, None]
    inside = (rows >= 0) & (rows < H)
    rows_c = np.clip(rows, 0, H - 1)
    prof = np.where(inside, sig[rows_c, cols], np.nan)              # (len(offs), W)
    bgp = np.where(inside, gray[rows_c, cols], np.nan)
    d = np.abs(offs)[:, None]
    ring = (d >= _BG_FROM) & (d <= _BG_TO)
    base = np.nanmedian(np.where(ring, prof, np.nan), axis=0)
    core = d <= 6
    p = np.where(core, prof, np.nan) - base
    peak = np.nanmax(p, axis=0)
    pos = np.clip(p, 0, None)
    integ = np.nansum(pos, axis=0)
    mean_off = np.nansum(pos * offs[:, None], axis=0) / np.maximum(integ, 1e-9)
    width = np.sqrt(np.nansum(pos * (offs[:, None] - mean_off) ** 2, axis=0)
                    / np.maximum(integ, 1e-9))
    noise = 1.4826 * np.nanmedian(np.abs(np.where(ring, prof, np.nan) - base), axis=0)
    bg_level = np.nanmedian(np.where(ring, bgp, np.nan), axis=0)
    valid = np.isfinite(peak) & (peak > np.maximum(8 * noise, 5.0)) & inside[len(offs) // 2]
    if bright_only and valid.any():
        valid &= bg_level >= 0.7 * np.percentile(bg_level[valid], 95)
    sat = np.where(core, np.where(inside, raw[rows_c, cols], 0), 0).max(axis=0) >= 250
    x = _detrended(integ, valid)
    xp = _detrended(peak, valid & ~sat)
    k = stats.gamma.fit(x[valid], floc=0)[0] if valid.sum() > 20 else np.nan
    # secondary: brightest other peak in the band, beyond 3 widths of the line
    far = (d > np.maximum(3 * np.nanmedian(width[valid]) if valid.any() else 6, 6)) & \
        (d <= _BAND_PX)
    other = np.nanmax(np.where(far, prof, np.nan), axis=0) - base
    ratio = np.clip(other / np.maximum(peak, 1e-9), 0, None)[valid]
    bg = _background(gray, centre)
    return LineStats(int(valid.sum()), _nanstd(x, valid), _nanstd(xp, valid & ~sat),
                     _corr_length(x, valid), float(k), float(np.nanmedian(width[valid])),
                     float(sat[valid].mean()) if valid.any() else np.nan, *bg,
                     float(np.percentile(ratio, 95)) if len(ratio) else np.nan,
                     float((ratio > 0.1).mean()) if len(ratio) else np.nan)


def _direction(sig: np.ndarray) -> str:
    """"u" if the brightest pixels spread more along u than along v, else "v"."""
    thr = np.percentile(sig, 99.7)
    v, u = np.nonzero(sig >= thr)
    return "u" if np.ptp(np.percentile(u, [5, 95])) >= np.ptp(np.percentile(v, [5, 95])) else "v"


def _centre_curve(sig: np.ndarray) -> np.ndarray:
    """(W,) row of the line per column: a robust quadratic through the columns' maxima."""
    sm = cv2.GaussianBlur(sig, (0, 0), 2.0)
    arg = np.argmax(sm, axis=0).astype(float)
    val = sm.max(axis=0)
    cols = np.arange(sig.shape[1], dtype=float)
    lo, hi = np.percentile(val, [50, 99])
    keep = val > lo + 0.3 * (hi - lo)
    coef = np.polyfit(cols[keep], arg[keep], 2)
    for _ in range(4):
        res = np.abs(np.polyval(coef, cols) - arg)
        keep &= res < max(3 * np.median(res[keep]), 2.0)
        coef = np.polyfit(cols[keep], arg[keep], 2)
    return np.polyval(coef, cols)


def _detrended(x: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """x divided by its own Gaussian-smoothed trend (σ 25 px) over the valid positions."""
    w = valid.astype(np.float32)
    xs = np.where(valid, x, 0).astype(np.float32)
    k = cv2.getGaussianKernel(int(6 * _TREND_PX) | 1, _TREND_PX).ravel()
    num = np.convolve(xs, k, mode="same")
    den = np.convolve(w, k, mode="same")
    trend = num / np.maximum(den, 1e-9)
    return np.where(valid, x / np.maximum(trend, 1e-9), np.nan)


def _nanstd(x: np.ndarray, valid: np.ndarray) -> float:
    return float(np.std(x[valid]) / np.mean(x[valid])) if valid.sum() > 5 else np.nan


def _corr_length(x: np.ndarray, valid: np.ndarray, max_lag: int = 40) -> float:
    """1/e length of the autocorrelation of x over valid positions (pairs both valid), px,
    linearly interpolated."""
    if valid.sum() < 30:
        return np.nan
    y = np.where(valid, x - np.nanmean(x[valid]), 0.0)
    m = valid.astype(float)
    acf = [1.0]
    for lag in range(1, max_lag):
        n = (m[lag:] * m[:-lag]).sum()
        acf.append((y[lag:] * y[:-lag]).sum() / max(n, 1) / np.mean(y[valid] ** 2))
    acf = np.array(acf)
    below = np.nonzero(acf < np.exp(-1))[0]
    if not len(below):
        return float(max_lag)
    i = below[0]
    return float(i - 1 + (acf[i - 1] - np.exp(-1)) / (acf[i - 1] - acf[i]))


def _background(gray: np.ndarray, centre: np.ndarray) -> tuple[float, float, float]:
    """Level, fine texture and coarse shading of the image away from the line (>20 px)."""
    H, W = gray.shape
    v = np.arange(H)[:, None]
    far = np.abs(v - centre[None, :]) > _BG_FROM
    smooth = cv2.GaussianBlur(gray, (0, 0), 8.0)
    level = float(np.median(gray[far]))
    texture = float(np.std((gray - smooth)[far]))
    shading = float(np.std(smooth[far]) / max(np.mean(smooth[far]), 1e-9))
    return level, texture, shading
