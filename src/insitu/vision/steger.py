"""Model-based sub-pixel line centres: per-column Gaussian peak fit and Steger's Hessian
ridge detector (Steger 1998, "An unbiased detector of curvilinear structures"). Both use the
detection stage, band and continuity of :mod:`insitu.vision.detect` (keywords there).

Gaussian: 3-point log-parabola through the column's raw maximum and its neighbours (exact for a
sampled Gaussian; 8-bit quantisation gives ≈ 0.01–0.02 px). Steger: see :func:`steger`.

Saturated columns (both methods): the clipped plateau's centre is the vertex of a
log-parabola fitted to its unsaturated flanks (weights ∝ value), else the centroid of the
pixels above half the maximum. Clipping breaks the Gaussian model, and for Steger the sampled
plateau's sharp corners alias into a phase-dependent bias of ≈ 0.05–0.1 px. The flanks are
taken above the column's own sloping background (:func:`~insitu.vision.profile.band_background`),
and only where they stand above it by more than the background changes from one side of the
line to the other (how wrong a straight background can be under the line), and only as far
as they fall without a break: beside a wall or a part's edge, where one side is lit and the
other dark, one background level for both put background pixels on the lit flank and moved
the vertex by about 1 px (0.24 mm on the step block).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.special import ndtr

from insitu.vision.chains import median_of
from insitu.vision.detect import MIN_PEAK, LineCentres, detect
from insitu.vision.profile import (
    FWHM_PER_SIGMA,
    as_image,
    fwhm,
    gather,
    saturation_level,
)
from insitu.vision.steger_kernel import (
    clipped_centres,
    plateau_centres,
    steger_columns,
    widths_and_clipping,
)

FLAT_PX = 2.5
"""Farthest (px) a flat top's centre (``clip``) may lie from the 3-point fit on it: the fit
jumps between the top's noisy maxima, up to ≈ 2.2 px on a top 6 px long (spent seed 8008);
a centre farther is not the top's own (the halo's clipped edge of a bright square beside
the stripe, spent seed 5003), and the fit is kept."""
_M = 3          # candidate rows: the detected peak ± _M


def _segment(mask, at):
    """(k, n) bool: the run of True rows of ``mask`` (k, n) holding row ``at`` (n,) of each
    column (none where that row is False)."""
    label, cols = np.cumsum(~mask, axis=0), np.arange(mask.shape[1])
    return mask & (label == label[at, cols]) & mask[at, cols]


def gaussian_peak(image: np.ndarray, min_peak: float = MIN_PEAK, window: int = 12, median: int = 3,
                  *, band=None, min_contrast: float = 20.0, snr: float = 6.0,
                  continuity: bool = True, saturation: float | None = None,
                  extend_ends: bool = True, upper: int = 0, scale: float | None = None,
                  allow=None, min_run: int = 0, ridge: bool = False,
                  noise: float | None = None, white=None, quiet=None, clip=None) -> LineCentres:
    """Per-column Gaussian peak: 3-point log-parabola through the raw maximum and its two
    neighbours (background subtracted). Saturated or degenerate columns: the plateau's centre
    from a log-parabola fitted to its unsaturated flanks, else the centroid of the pixels above
    half the maximum. Detection on the median-filtered image; the fit on the raw ``image``.
    clip: (H, W) bool, pixels counted saturated besides those at ``saturation``, in a column
    with none at it where their run through the maximum ends inside the band (a colour frame
    measured in the sum of its channels: where one channel is clipped, the sum is flat topped
    below its own full scale; a halo clipped wider than the band is left to the fit); the
    3-point fit is kept where that centre lies more than :data:`FLAT_PX` from it. Other
    arguments as :func:`gray_centroid`; width: FWHM px.
    """
    img = as_image(image)
    det = detect(img, median, band, window, min_peak, min_contrast, snr, continuity,
                 extend_ends=extend_ends, upper=upper, scale=scale, allow=allow,
                 min_run=min_run, ridge=ridge, noise=noise, white=white, quiet=quiet)
    c, r, bg, w, unit = det.cols, det.row, det.bg, det.window, det.full_scale / 255
    sat = saturation_level(img, saturation, scale)
    x = np.arange(-w, w + 1)[:, None]
    raw, inside = gather(img, r[None, :] + x, c)
    g = np.where(inside, raw - bg, 0)
    j = w - 2 + np.argmax(g[w - 2:w + 3], axis=0)
    a, b, d = (np.take_along_axis(g, (j + s)[None, :], 0)[0] for s in (-1, 0, 1))
    peak = np.take_along_axis(raw, j[None, :], 0)[0]
    saturated, flat = peak >= sat, raw >= sat
    if clip is not None:          # a flat top below full scale, both its flanks in the band
        top = _segment(gather(clip, r[None, :] + x, c)[0] > 0, j)
        flat = flat | (top & ~(top[0] | top[-1] | flat.any(axis=0)))
    on_top = np.take_along_axis(flat, j[None, :], 0)[0] & ~saturated
    la, lb, ld = (np.log(np.maximum(t, 0.5 * unit)) for t in (a, b, d))
    den = la - 2 * lb + ld
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = 0.5 * (la - ld) / den
        width = np.nan_to_num(FWHM_PER_SIGMA * np.sqrt(-1.0 / den))
    fit = (den < 0) & (np.abs(delta) <= 1)
    v = r + (j - w) + np.where(fit & ~saturated, delta, 0.0)
    rest = ~fit | saturated | on_top
    if rest.any():
        gs, ins = g[:, rest], inside[:, rest]
        top = gs.max(axis=0)
        flank = r[rest] + plateau_centres(raw[:, rest], ins, flat[:, rest], det.noise, unit)
        own = (fit & on_top)[rest] & ~(np.abs(flank - v[rest]) <= FLAT_PX)
        v[rest] = np.where(own, v[rest], flank)
        width[rest] = np.where(own, width[rest], fwhm(gs, ins, top - det.contrast[rest], top))
        on_top[rest] &= ~own
    saturated = saturated | on_top
    return LineCentres(c.astype(np.float64), v.astype(np.float64), peak.astype(np.float64),
                       width.astype(np.float64), det.contrast.astype(np.float64), saturated,
                       det.ambiguous, det.full_scale)


def gaussian_kernels(sigma: float, radius: int):
    """Correlation kernels (2·radius+1,) float32 of the pixel-integrated Gaussian and its first
    and second derivative, normalised so that they are exact on constants, ramps, parabolas."""
    x = np.arange(-radius, radius + 1, dtype=np.float64)

    def phi(t):
        return np.exp(-t * t / (2 * sigma**2)) / (np.sqrt(2 * np.pi) * sigma)

    h0 = ndtr((x + 0.5) / sigma) - ndtr((x - 0.5) / sigma)
    h1 = phi(x - 0.5) - phi(x + 0.5)
    h2 = -(x + 0.5) / sigma**2 * phi(x + 0.5) + (x - 0.5) / sigma**2 * phi(x - 0.5)
    h0 /= h0.sum()
    h1 /= (x * h1).sum()
    h2 -= h2.mean()
    h2 /= (x * x * h2).sum() / 2
    return h0.astype(np.float32), h1.astype(np.float32), h2.astype(np.float32)


@lru_cache(maxsize=16)
def _kernels(sigma: float, radius: int) -> np.ndarray:
    """(3, 2·radius + 1) float32: :func:`gaussian_kernels` stacked, as the compiled pass
    takes them."""
    return np.stack(gaussian_kernels(sigma, radius))


def steger(image: np.ndarray, sigma: float | None = None, min_peak: float = MIN_PEAK,
           window: int = 12, median: int = 3, *, band=None, min_contrast: float = 20.0,
           snr: float = 6.0, continuity: bool = True, saturation: float | None = None,
           min_curvature: float | None = None, extend_ends: bool = True,
           upper: int = 0, scale: float | None = None, allow=None,
           min_run: int = 0, ridge: bool = False, noise: float | None = None,
           white=None, quiet=None, across: bool = False) -> LineCentres:
    """Steger centres of a line running along the rows of ``image`` (tilts to ≈ 60° work).

    Per column: Gaussian derivatives at the 7 rows around the detected peak; the Hessian's
    eigenvector of the most negative eigenvalue λ is the normal n; t = -(n·∇I)/λ. A line pixel
    has |t·n_u|, |t·n_v| ≤ 0.5 px (0.6: room for the Taylor step's overshoot) and -λ ≥
    min_curvature; the strongest is refined to the crossing of its own column: the root of
    n·∇I along v from a cubic Hermite fit of n·∇I and n·H·e_v between two rows (removes the
    Taylor step's O(t³/σ²) bias of up to 0.04 px), so u is the column (c + t·n_u if no root).

    image: (H, W) uint8/uint16/float32. sigma: Gaussian scale, px (None: σ = max(1, FWHM/2√3)
    from the median FWHM, Steger's σ ≥ w/√3 for a bar of half-width w). min_curvature: least
    -λ, gray values/px² (None: 0.1 · min_contrast / σ², min_contrast of full scale as
    detect takes it). across: a column with no line pixel by the Hessian's test (an albedo
    edge across the line, where the derivatives along u outweigh those across) is measured
    down the column alone (n = (0, 1)), where its pixel passes that test in one dimension.
    Other keywords as gray_centroid.
    width: FWHM px of the filtered column. Within ≈ 3.5σ of the frame's border the clipped
    patch biases the centre.
    """
    img = as_image(image)
    det = detect(img, median, band, window, min_peak, min_contrast, snr, continuity,
                 extend_ends=extend_ends, upper=upper, scale=scale, allow=allow,
                 min_run=min_run, ridge=ridge, noise=noise, white=white, quiet=quiet)
    c, r, n, w, unit = det.cols, det.row, len(det.cols), det.window, det.full_scale / 255
    level = saturation_level(img, saturation, scale)
    width, sat = widths_and_clipping(det.pre, img, r.astype(np.int64), c.astype(np.int64), w,
                                     (det.gmax - det.contrast + det.gmax) / 2,
                                     np.float32(level))
    if sigma is None:
        own = width if det.carried.all() else width[~det.carried]
        sigma = max(1.0, median_of(own) / (2 * np.sqrt(3))) if n else 1.0
    if min_curvature is None:
        min_curvature = 0.1 * min_contrast * unit / sigma**2
    h = _kernels(float(sigma), int(np.ceil(3.5 * sigma)))
    u, v, found = steger_columns(img, r.astype(np.int64), c.astype(np.int64), h, _M + 1,
                                 np.float32(min_curvature), bool(across))
    if sat.any():                                 # clipped plateau: the flank fit instead
        v[sat] = r[sat] + clipped_centres(img, r[sat].astype(np.int64),
                                          c[sat].astype(np.int64), w, np.float32(level),
                                          det.noise, unit)
        u[sat], found[sat] = c[sat], True
    keep = found & np.isfinite(u) & np.isfinite(v)
    return LineCentres(u[keep].astype(np.float64), v[keep].astype(np.float64),
                       det.gmax[keep].astype(np.float64), width[keep],
                       det.contrast[keep].astype(np.float64), sat[keep], det.ambiguous[keep],
                       det.full_scale)
