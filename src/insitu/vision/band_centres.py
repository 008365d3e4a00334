"""Centres of several lines in one frame, each only inside its own band.

A frame that holds K lines is searched K times, each time only in the strip of rows (or
columns) one line's band covers — a few per cent of the frame — with the scan's extraction
(:func:`~insitu.vision.extract.extract_centres`: the detection, the choice between two peaks,
the smoothing along the line), so each line is found exactly as a line alone in its frame
would be, by the same code. A centre is the line's only where its band holds it, away from
the band's ends: a peak on a band's end is the flank of a stripe beyond it, and a line whose
band another band overlaps has no centre there (:func:`insitu.reconstruct.bands.exclusive`
makes the bands so).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from insitu.vision.detect import MIN_PEAK, LineCentres
from insitu.vision.extract import CentreSettings, extract_centres

PAD_PX = 16
"""Rows (columns) beside a band's strip read with it: the detection's median filter and its
background at ±12 px from the peak see the same pixels as in the whole frame."""


def centres_in_bands(image: np.ndarray, bands: Sequence,
                     settings: CentreSettings = CentreSettings(), edge_px: float = 1.0,
                     pixel_bits: int | None = None, level: float = 0.0) -> list[LineCentres]:
    """One :class:`~insitu.vision.detect.LineCentres` per band (each a
    :class:`~insitu.reconstruct.bands.Band`-like object: ``lo``, ``hi`` (n,) px across the
    line per position along it, NaN where it cannot be; ``along_rows``; ``side``) of the
    frame ``image`` (H, W): that line's centres found inside its band only, at least
    ``edge_px`` from the band's ends. ``pixel_bits``: the frame's significant bits.
    ``level`` (gray values > 0): room light the frame holds beyond one line's exposure; a
    peak must stand :data:`~insitu.vision.detect.MIN_PEAK` above it, as in a frame of one
    line (a stripe too faint for that floor alone passes it on the level: the simulator's
    insert, binning 2, renders 101 and 104, packed max 0.083 and 0.077 mm at 21-24 DN of
    contrast)."""
    return [_one(image, b, settings, edge_px, pixel_bits, level) for b in bands]


def _one(image: np.ndarray, band, settings: CentreSettings, edge_px: float,
         pixel_bits: int | None, level: float) -> LineCentres:
    empty = LineCentres(*(np.zeros(0) for _ in range(5)))
    ok = np.isfinite(band.lo) & np.isfinite(band.hi) & (band.lo <= band.hi)
    if not ok.any():
        return empty
    size = image.shape[0] if band.along_rows else image.shape[1]
    a = int(max(np.floor(np.nanmin(band.lo[ok])) - PAD_PX, 0))
    b = int(min(np.ceil(np.nanmax(band.hi[ok])) + PAD_PX + 1, size))
    if b - a < 3:
        return empty
    strip = image[a:b] if band.along_rows else image[:, a:b]
    lo, hi = np.where(ok, band.lo - a, np.nan), np.where(ok, band.hi - a, np.nan)
    c = extract_centres(strip, settings, (lo, hi), band.along_rows, band.side, pixel_bits)
    if band.along_rows:
        c = replace(c, v=c.v + a)
        along, across = c.u, c.v
    else:
        c = replace(c, u=c.u + a)
        along, across = c.v, c.u
    i = np.clip(np.round(along).astype(np.int64), 0, len(band.lo) - 1)
    with np.errstate(invalid="ignore"):
        keep = (across >= band.lo[i] + edge_px) & (across <= band.hi[i] - edge_px)
    if level > 0:
        keep &= c.peak >= MIN_PEAK * c.full_scale / 255 + level
    return _take(c, keep)


def _take(c: LineCentres, keep: np.ndarray) -> LineCentres:
    """The centres where ``keep`` (N,) is True."""
    n = len(c)
    return replace(c, **{f: getattr(c, f)[keep] for f in c.__dataclass_fields__
                         if isinstance(getattr(c, f), np.ndarray) and len(getattr(c, f)) == n})
