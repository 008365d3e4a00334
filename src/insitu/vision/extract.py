"""Line centres as the measurement uses them: extraction settings, and edge-preserving
smoothing along the line.

Speckle makes the centre of each column wander by a fraction of a pixel, correlated over a few
columns; a local quadratic fit over a window of columns averages that out while keeping slopes
and curvature. The line is cut where it jumps (steps, occlusion), so edges stay sharp, and
runs on across the few columns a dark speckle blotch or a dropped spike takes out.

How far the wander is correlated depends on the rig (the speckle grain in the image, the
surface): 2 px on our simulator, 4 px on independent recordings. So the window is sized to the
frame: at least ``smooth_grains`` correlation lengths of the frame's own wander
(:func:`wander_correlation_px`), never less than ``smooth_half_window``."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from functools import lru_cache

import numpy as np
from scipy.signal import savgol_coeffs

from insitu.errors import ConfigError
from insitu.formats.validation import one_of
from insitu.vision.centres import CENTRE_METHODS, line_centres
from insitu.vision.detect import LineCentres
from insitu.vision.laser_image import check_bits
from insitu.vision.peak_rows import band_extent, per_column
from insitu.vision.profile import frame_noise
from insitu.vision.smooth_kernel import kept_and_smoothed, run_edges, wander_scale


@dataclass(frozen=True)
class CentreSettings:
    """How centres are extracted. The paper's: gray centroid (Eq. 7), no smoothing. Ours
    (default): Steger's detector, then smoothing along the line (benchmarks/accuracy.py).
    ``method``: a key of :data:`~insitu.vision.centres.CENTRE_METHODS` ("gray" uses k,
    subtract and background: K from the local background and the peak, not the peak alone);
    ConfigError for another. ``smooth_grains``: the smoothing window in correlation lengths
    of the frame's wander (0: fixed ``smooth_half_window``). ``extend_ends``: a line's
    ends carried on where its peak, filtered along the row, still passes the detector's
    thresholds (:func:`~insitu.vision.detect.carry_ends`; not in the paper's mode, nor in
    a version-1 height calibration). A height calibration stores the settings it was made with; a
    scan uses the same."""

    method: str = "steger"
    k: float = 0.3
    subtract: bool = False
    smooth_half_window: int = 7
    jump_px: float = 1.0
    end_fraction: float = 0.0
    smooth_grains: float = 7.0
    background: bool = True
    extend_ends: bool = True

    def __post_init__(self) -> None:
        if self.method not in CENTRE_METHODS:
            raise ConfigError(f"centre method {self.method!r}: expected "
                              f"{one_of(CENTRE_METHODS)}")

    def to_dict(self) -> dict:
        return asdict(self)


CROP_MARGIN = 64
"""Pixels round the band that the centres of a banded frame are measured in (:func:`band_crop`):
the median filter, 2 × the default ±12-row window for a clipped plateau's run and its flanks,
Steger's derivatives of a line up to ≈ 25 px wide."""
PAPER_SETTINGS = CentreSettings(method="gray", k=0.5, smooth_half_window=0, smooth_grains=0.0,
                                background=False, extend_ends=False)
MAX_HALF_WINDOW = 25


def extract_centres(image: np.ndarray, settings: CentreSettings = CentreSettings(),
                    band: tuple[np.ndarray, np.ndarray] | None = None,
                    along_rows: bool = True, upper: int = 0,
                    pixel_bits: int | None = None, crop: bool = True) -> LineCentres:
    """Centres of the line in ``image`` (H, W): one per column when the line runs along the
    rows, else one per row (the image is searched across the line either way). ``band``:
    (lo, hi) per column (rows) or per row (columns) where the line can be; ghosts outside it
    are ignored, and only the band's rectangle (:func:`band_crop`) is read (``crop`` False:
    the whole frame is filtered; the centres are the same). ``upper``: the side of the line's
    cross coordinate a higher surface puts it (+1 larger, −1 smaller, 0 unknown;
    :func:`~insitu.vision.detect.detect`). ``pixel_bits``: the frame's significant bits (a
    Mono12 camera's: 12; None: the dtype's), which every threshold is a fraction of. u, v are
    image coordinates in both cases."""
    view = np.asarray(image) if along_rows else np.asarray(image).T
    options = {o: getattr(settings, o) for o in CENTRE_METHODS[settings.method].options}
    if band is None or not crop:
        img, r0, c0 = np.ascontiguousarray(view), 0, 0
    else:
        check_bits(view, pixel_bits)
        (rows, cols), band = band_crop(view.shape, band)
        img, r0, c0 = np.ascontiguousarray(view[rows, cols]), rows.start, cols.start
        options["noise"] = frame_noise(view)
    c = line_centres(img, settings.method, direction="rows", band=band, upper=upper,
                     pixel_bits=pixel_bits, **options)
    if r0 or c0:
        c = replace(c, u=c.u + c0, v=c.v + r0)
    if settings.smooth_half_window and len(c):
        half = settings.smooth_half_window
        order, pieces = _pieces(c, settings.jump_px)
        if settings.smooth_grains:
            grain = _wander(c.v[order], pieces)
            half = int(np.clip(np.ceil(settings.smooth_grains * grain / 2), half,
                               max(half, MAX_HALF_WINDOW)))
        c = _smooth(c, order, pieces, half, settings.jump_px, settings.end_fraction)
    return c if along_rows else replace(c, u=c.v, v=c.u)


def band_crop(shape: tuple[int, int], band, margin: int = CROP_MARGIN
              ) -> tuple[tuple[slice, slice], tuple[np.ndarray, np.ndarray]]:
    """The rectangle (rows, cols) of a frame of ``shape`` (H, W) that holds ``band`` (lo, hi)
    (rows per column, each (W,) or scalar; NaN: a column not searched) and ``margin`` px
    round it, clipped to the frame, and the band in the rectangle's rows and columns. Every
    pixel the centre methods read about a line inside the band (the median filter, the ±window
    rows, a clipped plateau's run, Steger's derivatives) lies in the margin, so the rectangle's
    centres are the frame's."""
    H, W = shape
    lo, hi = (np.ascontiguousarray(per_column(b, W)) for b in band)
    first, last, least, most = band_extent(lo, hi, H)
    if first < 0:
        return (slice(0, min(H, 1)), slice(0, min(W, 1))), (lo[:1], hi[:1])
    r0 = int(min(max(np.floor(least) - margin, 0), H - 1))
    r1 = int(min(max(np.ceil(most) + margin + 1, r0 + 1), H))
    c0, c1 = max(first - margin, 0), min(last + margin + 1, W)
    return (slice(r0, r1), slice(c0, c1)), (lo[c0:c1] - r0, hi[c0:c1] - r0)


def runs(u: np.ndarray, v: np.ndarray, jump_px: float) -> list[slice]:
    """Slices of (u, v) (sorted by u) where columns follow each other and v does not jump
    off the line's own slope (:func:`~insitu.vision.smooth_kernel.jumps`)."""
    edges = _run_edges(u, v, jump_px)
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def _run_edges(u: np.ndarray, v: np.ndarray, jump_px: float) -> np.ndarray:
    """The :func:`runs` as (k + 1,) indices: run i is [edges[i], edges[i + 1]) (for u
    non-empty; [0, 0] for none; :func:`~insitu.vision.smooth_kernel.run_edges`)."""
    if not len(u):
        return np.zeros(2, np.int64)
    return run_edges(np.asarray(u, np.float64), np.asarray(v, np.float64), float(jump_px))


def wander_correlation_px(c: LineCentres, jump_px: float = 1.0, min_run: int = 80,
                          max_lag: int = 24) -> float:
    """How many columns the centres' wander is correlated over, px (the integral scale
    1 + 2 Σ ρ_k of its autocorrelation up to the first zero), from the runs of at least
    ``min_run`` columns, about a 61-column quadratic trend; 0 when no run is long enough."""
    if len(c) < min_run:
        return 0.0
    order, edges = _pieces(c, jump_px)
    return _wander(c.v[order], edges, min_run, max_lag)


def _pieces(c: LineCentres, jump_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The order that sorts ``c`` by u, and the :func:`_run_edges` of the sorted centres."""
    order = np.argsort(c.u, kind="stable")
    return order, _run_edges(c.u[order], c.v[order], jump_px)


def _wander(v: np.ndarray, edges: np.ndarray, min_run: int = 80, max_lag: int = 24) -> float:
    """:func:`wander_correlation_px` of the centres' v (n,) sorted by u, cut into runs at
    ``edges``: the autocorrelation of each run of at least ``min_run`` points about its
    Savitzky–Golay quadratic trend (scipy's savgol_filter, mode "interp", over 61 points, or
    ``min_run`` − 1 in a run of 61 or fewer), summed over the runs
    (:func:`~insitu.vision.smooth_kernel.wander_scale`)."""
    start, stop = edges[:-1], edges[1:]
    long = stop - start >= min_run
    if not long.any():
        return 0.0
    a, b = start[long], stop[long]
    sizes = (61, min_run - 1)
    coeffs, ends = _stacked_savgol(sizes)
    return float(wander_scale(np.asarray(v, np.float64), a, b, (b - a <= 61).astype(np.int64),
                              np.array(sizes), coeffs, ends, max_lag))


@lru_cache(maxsize=8)
def _stacked_savgol(sizes: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_savgol_matrices` of each window size, stacked and zero-padded:
    (m, K) and (m, K, K), K the largest size."""
    K = max(sizes)
    coeffs, ends = np.zeros((len(sizes), K)), np.zeros((len(sizes), K, K))
    for i, k in enumerate(sizes):
        coeffs[i, :k], ends[i, :k, :k] = _savgol_matrices(k)
    return coeffs, ends


@lru_cache(maxsize=8)
def _savgol_matrices(window: int) -> tuple[np.ndarray, np.ndarray]:
    """The interior's convolution coefficients (window,) and the least-squares quadratic's
    hat matrix (window, window) of the positions 0 … window − 1."""
    V = np.vander(np.arange(window, dtype=np.float64), 3)
    return savgol_coeffs(window, 2), V @ np.linalg.pinv(V)


def smooth_centres(c: LineCentres, half_window: int = 7, jump_px: float = 1.0,
                   end_fraction: float = 0.0, drop_short: int = 3) -> LineCentres:
    """Local quadratic fit of v against the column over 2·half_window + 1 columns, along each
    stretch of the line that no discontinuity cuts.

    Pieces: columns that follow each other with v not stepping off the line by more than
    ``jump_px`` (its slope in the frame allowed for:
    :func:`~insitu.vision.smooth_kernel.jumps`). At each
    end of a piece, columns whose peak is below ``end_fraction`` of its median peak are
    dropped (0, the default: none; a version-1 height calibration drops them at 0.5 as
    the blurred tail beyond an edge). Speckle dims a line's last columns as often as blur
    does, and a line clipped by an oblique edge fades over several columns still on the top:
    the dropped ends jumped inwards by 0 to 7 px, the edges a part is located by with them.
    Pieces shorter than ``drop_short`` columns are dropped as isolated (spurious)
    detections. Stretches: the pieces left, joined across gaps of at most ``half_window``
    columns where v runs on (within ``jump_px`` of the line's slope times the gap):
    a dark speckle blotch, or a spike dropped, does not cut the line; a step or an occlusion
    does. Each point gets the quadratic fitted to its stretch's points in the window centred
    on it, shifted to stay inside the stretch at its ends (Savitzky–Golay's interp mode, which
    this is on a stretch without gaps); a stretch shorter than the window is fitted whole (a
    straight line below 5 points). Without the joins, the pieces between blotches were
    shorter than the window and kept their raw centres: 7 % of the points of the independent
    recording, its worst.
    """
    if len(c) == 0 or half_window < 1:
        return c
    order, edges = _pieces(c, jump_px)
    return _smooth(c, order, edges, half_window, jump_px, end_fraction, drop_short)


def _smooth(c: LineCentres, order: np.ndarray, edges: np.ndarray, half_window: int,
            jump_px: float, end_fraction: float, drop_short: int = 3) -> LineCentres:
    """:func:`smooth_centres` of ``c`` (n ≥ 1), given the order sorting it by u and the
    :func:`_run_edges` of the sorted centres
    (:func:`~insitu.vision.smooth_kernel.kept_and_smoothed`)."""
    u = c.u[order]
    keep, v = kept_and_smoothed(np.round(u).astype(np.int64), np.asarray(c.v[order], np.float64),
                                np.asarray(c.peak[order], np.float64), edges, int(half_window),
                                float(jump_px), float(end_fraction), int(drop_short))
    idx = order[keep]
    fields = {f: getattr(c, f)[idx] for f in c.__dataclass_fields__
              if isinstance(getattr(c, f), np.ndarray) and len(getattr(c, f)) == len(c)}
    fields["v"] = v
    return replace(c, **fields)
