"""Line centres as the measurement uses them: extraction settings, and edge-preserving
smoothing along the line.

Speckle makes the centre of each column wander by a fraction of a pixel, correlated over a few
columns; a local quadratic fit over a window of columns averages that out while keeping slopes
and curvature. The line is cut where it jumps (steps, occlusion), so edges stay sharp.

How far the wander is correlated depends on the rig (the speckle grain in the image, the
surface): 2 px on our simulator, 4 px on independent recordings. So the window is sized to the
frame: at least ``smooth_grains`` correlation lengths of the frame's own wander
(:func:`wander_correlation_px`), never less than ``smooth_half_window``."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np
from scipy.signal import savgol_filter

from insitu.errors import ConfigError
from insitu.formats.validation import one_of
from insitu.vision.centres import CENTRE_METHODS, line_centres
from insitu.vision.detect import LineCentres


@dataclass(frozen=True)
class CentreSettings:
    """How centres are extracted. The paper's: gray centroid (Eq. 7), no smoothing. Ours
    (default): Steger's detector, then smoothing along the line (benchmarks/accuracy.py).
    ``method``: a key of :data:`~insitu.vision.centres.CENTRE_METHODS` ("gray" uses k,
    subtract and background: K from the local background and the peak, not the peak alone);
    ConfigError for another. ``smooth_grains``: the smoothing window in correlation lengths
    of the frame's wander (0: fixed ``smooth_half_window``). A height calibration stores the
    settings it was made with; a scan uses the same."""

    method: str = "steger"
    k: float = 0.3
    subtract: bool = False
    smooth_half_window: int = 7
    jump_px: float = 1.0
    end_fraction: float = 0.5
    smooth_grains: float = 7.0
    background: bool = True

    def __post_init__(self) -> None:
        if self.method not in CENTRE_METHODS:
            raise ConfigError(f"centre method {self.method!r}: expected "
                              f"{one_of(CENTRE_METHODS)}")

    def to_dict(self) -> dict:
        return asdict(self)


PAPER_SETTINGS = CentreSettings(method="gray", k=0.5, smooth_half_window=0, smooth_grains=0.0,
                                background=False)
MAX_HALF_WINDOW = 25


def extract_centres(image: np.ndarray, settings: CentreSettings = CentreSettings(),
                    band: tuple[np.ndarray, np.ndarray] | None = None,
                    along_rows: bool = True) -> LineCentres:
    """Centres of the line in ``image`` (H, W): one per column when the line runs along the
    rows, else one per row (the image is searched across the line either way). ``band``:
    (lo, hi) per column (rows) or per row (columns) where the line can be; ghosts outside it
    are ignored. u, v are image coordinates in both cases."""
    img = image if along_rows else cv2.transpose(image)
    options = {o: getattr(settings, o) for o in CENTRE_METHODS[settings.method].options}
    c = line_centres(img, settings.method, direction="rows", band=band, **options)
    if settings.smooth_half_window:
        half = settings.smooth_half_window
        if settings.smooth_grains:
            grain = wander_correlation_px(c, settings.jump_px)
            half = int(np.clip(np.ceil(settings.smooth_grains * grain / 2), half,
                               max(half, MAX_HALF_WINDOW)))
        c = smooth_centres(c, half, settings.jump_px, settings.end_fraction)
    return c if along_rows else replace(c, u=c.v, v=c.u)


def runs(u: np.ndarray, v: np.ndarray, jump_px: float) -> list[slice]:
    """Slices of (u, v) (sorted by u) where columns follow each other and v does not jump."""
    brk = np.nonzero((np.diff(u) > 1.5) | (np.abs(np.diff(v)) > jump_px))[0] + 1
    edges = np.concatenate([[0], brk, [len(u)]])
    return [slice(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def wander_correlation_px(c: LineCentres, jump_px: float = 1.0, min_run: int = 80,
                          max_lag: int = 24) -> float:
    """How many columns the centres' wander is correlated over, px (the integral scale
    1 + 2 Σ ρ_k of its autocorrelation up to the first zero), from the runs of at least
    ``min_run`` columns, about a 61-column quadratic trend; 0 when no run is long enough."""
    if len(c) < min_run:
        return 0.0
    order = np.argsort(c.u, kind="stable")
    u, v = c.u[order], c.v[order]
    acf = np.zeros(max_lag + 1)
    for r in runs(u, v, jump_px):
        if r.stop - r.start >= min_run:
            res = v[r] - savgol_filter(v[r], 61 if r.stop - r.start > 61 else min_run - 1, 2)
            res -= res.mean()
            f = np.fft.rfft(res, 2 * len(res))
            acf += np.fft.irfft(f * np.conj(f))[:max_lag + 1]
    if acf[0] <= 0:
        return 0.0
    rho = acf / acf[0]
    end = np.argmax(rho[1:] <= 0) + 1 if (rho[1:] <= 0).any() else len(rho)
    return float(1.0 + 2.0 * rho[1:end].sum())


def smooth_centres(c: LineCentres, half_window: int = 7, jump_px: float = 1.0,
                   end_fraction: float = 0.5, drop_short: int = 3) -> LineCentres:
    """Savitzky–Golay (quadratic, 2·half_window + 1 columns) within each continuous run.

    Runs shorter than the window keep their raw centres; runs shorter than ``drop_short``
    columns are dropped as isolated (spurious) detections. ``jump_px``: a step in v between
    neighbouring columns larger than this cuts the line. ``end_fraction``: at each end of a
    run, columns whose peak is below this fraction of the run's median peak are the blurred
    tail of the line beyond an edge and are dropped, so a run ends where the light does.
    """
    if len(c) == 0 or half_window < 1:
        return c
    order = np.argsort(c.u, kind="stable")
    u, v = c.u[order], c.v[order]
    out = v.copy()
    keep = np.ones(len(u), bool)
    w = 2 * half_window + 1
    peak = c.peak[order]
    for r in runs(u, v, jump_px):
        bright = np.nonzero(peak[r] >= end_fraction * np.median(peak[r]))[0]
        a, b = r.start + bright[0], r.start + bright[-1] + 1
        keep[r.start:a] = keep[b:r.stop] = False
        if b - a < drop_short:
            keep[a:b] = False
        elif b - a >= w:
            out[a:b] = savgol_filter(v[a:b], w, 2, mode="interp")
    idx = order[keep]
    fields = {f: getattr(c, f)[idx] for f in c.__dataclass_fields__
              if isinstance(getattr(c, f), np.ndarray) and len(getattr(c, f)) == len(c)}
    fields["v"] = out[keep]
    return replace(c, **fields)
