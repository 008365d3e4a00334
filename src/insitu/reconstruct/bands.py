"""Where each commanded line can appear in the image — its band — from the rig's geometry and
a height range; the bands of lines drawn in one exposure made exclusive; lines packed into
frames so that their bands do not overlap.

A line's light sheet meets every surface between two heights on a strip of the image: the
sheet between those heights, projected. With a sheet height model (ours, Method 2) that is
the sheet the calibration saw, the head's distortion included; else the nominal plane through
the pivot (Li et al. Eq. 2), which misses it by up to the distortion. A band is that strip
widened by a margin (the calibration's error, the line's own width); a centre in it can only
be that line's when no other line's band holds the same pixel. Lines whose bands lie apart
can be drawn in one exposure (:func:`stride`, :func:`frames`): the narrower the height range,
the closer they may be.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from insitu.geometry.beams import light_plane
from insitu.geometry.camera import CameraModel
from insitu.reconstruct.plane import line_runs_along_rows
from insitu.reconstruct.plate_models import SheetHeightModel
from insitu.reconstruct.turned_sheet import (
    TurnedSheetModel,
    same_direction,
    turn_to_y,
    turned_offset,
)

_SAMPLES = 96
_HEIGHTS = 5


@dataclass(frozen=True)
class Packing:
    """The margins lines are packed with. ``height_mm``: added below and above the heights a
    survey measured (its noise, a surface just beside its lines); ``margin_px``: each band
    widened on both sides (the calibration's error, the centre's wander); ``guard_px``: the
    least gap between the bands of one frame; ``edge_px``: a centre this close to its band's
    end is a flank of a stripe beyond, not a peak (px of the frame); ``most_lines``: at most
    this many lines in one frame when packing as the heights allow (each line's band also
    gathers the room light of K lines' exposure and their stray light: on the simulator's
    freeform and tilted plane 8–11 lines a frame cost 1.3–2.4 × the RMS, 3–7 lines under
    1.05 ×)."""

    height_mm: float = 2.0
    margin_px: float = 1.0
    guard_px: float = 2.0
    edge_px: float = 0.5
    most_lines: int = 4


@dataclass(frozen=True)
class Band:
    """Where a line can be: ``along_rows`` (it crosses the columns) → ``lo``, ``hi`` (W,) rows
    per column; else (H,) columns per row; NaN where it cannot be. ``side``: which way a
    higher surface moves it across itself (+1 to larger rows/columns, −1, 0 unknown)."""

    lo: np.ndarray
    hi: np.ndarray
    along_rows: bool
    side: int

    @property
    def searched(self) -> np.ndarray:
        """(n,) bool: where the line can be at all."""
        with np.errstate(invalid="ignore"):
            return np.isfinite(self.lo) & np.isfinite(self.hi) & (self.lo <= self.hi)

    def middle(self) -> float:
        """Its median cross coordinate, px (NaN when it is nowhere)."""
        ok = self.searched
        return float(np.median((self.lo[ok] + self.hi[ok]) / 2)) if ok.any() else np.nan

    def holds(self, along: np.ndarray, across: np.ndarray, edge_px: float = 0.0) -> np.ndarray:
        """(N,) bool: the points (``along`` the line, ``across`` it) px lie inside, at least
        ``edge_px`` from its ends (a peak on a band's end is the flank of a stripe beyond)."""
        i = np.clip(np.round(along).astype(np.int64), 0, len(self.lo) - 1)
        lo, hi = self.lo[i], self.hi[i]
        with np.errstate(invalid="ignore"):
            return (across >= lo + edge_px) & (across <= hi - edge_px)


class Sheets:
    """The light sheets of a rig's lines as the reconstruction knows them: ``model``'s for
    lines along y and ``cross_model``'s for its crossed lines when they are sheet models,
    else the nominal plane through the pivot. ``camera``: the one the model was fitted
    through (the one the centres are measured in)."""

    def __init__(self, camera: CameraModel, pivot_height_mm: float, telecentric: bool = False,
                 model=None, cross_model: TurnedSheetModel | None = None):
        self.camera, self.H, self.telecentric = camera, float(pivot_height_mm), telecentric
        self.model = model if isinstance(model, SheetHeightModel) else None
        self.cross = cross_model

    def calibrated(self, start, end) -> bool:
        """Whether the line's sheet is a calibrated one (not the nominal plane)."""
        return self._sheet(start, end)[0] is not None

    def _sheet(self, start, end):
        if abs(start[0] - end[0]) <= 1e-9 and self.model is not None:
            return self.model, None
        if self.cross is not None and same_direction(start, end, self.cross.angle_deg):
            return self.cross.sheet, self.cross.angle_deg
        return None, None

    def points(self, start, end, s: np.ndarray, z: float) -> np.ndarray:
        """(n, 3) world mm: the line's sheet at height ``z`` on the beams to the commanded
        points start + s (end − start), s (n,)."""
        a, b = np.asarray(start, float), np.asarray(end, float)
        xy = a + s[:, None] * (b - a)
        sheet, angle = self._sheet(a, b)
        if sheet is None:
            plane = light_plane(self.H, a, b, self.telecentric)
            axis = 0 if abs(plane[0]) >= abs(plane[1]) else 1
            p = np.column_stack([xy, np.full(len(xy), float(z))])
            p[:, axis] = -(plane[1 - axis] * p[:, 1 - axis] + plane[2] * z + plane[3]) / plane[axis]
            return p
        R = turn_to_y(angle)[:2, :2] if angle is not None else np.eye(2)
        x = turned_offset(a, b, angle) if angle is not None else float(a[0])
        Y = (xy @ R.T)[:, 1] * (sheet.H - z) / sheet.H
        Z = np.full(len(Y), float(z))
        p = np.column_stack([sheet.sheet_x(x, Y, Z), Y, Z])
        return p if angle is None else p @ turn_to_y(angle)

    def band(self, start, end, z_range: tuple[float, float], margin_px: float) -> Band:
        """The line's :class:`Band` for surfaces within ``z_range`` (low, high) mm, widened
        by ``margin_px`` on each side."""
        along_rows = line_runs_along_rows(self.camera, start, end)
        along, across = (0, 1) if along_rows else (1, 0)
        n = self.camera.width if along_rows else self.camera.height
        grid = np.arange(n, dtype=np.float64)
        s = np.linspace(-0.05, 1.05, _SAMPLES)
        heights = np.linspace(z_range[0], z_range[1], _HEIGHTS)
        edges = np.full((len(heights), n), np.nan)
        for k, z in enumerate(heights):
            uv = self.camera.project(self.points(start, end, s, z))
            uv = uv[np.isfinite(uv).all(axis=1)]
            if len(uv) < 2:
                return Band(np.full(n, np.nan), np.full(n, np.nan), along_rows, 0)
            o = np.argsort(uv[:, along])
            edges[k] = np.interp(grid, uv[o, along], uv[o, across], left=np.nan, right=np.nan)
        rise = (edges[-1] - edges[0])[np.isfinite(edges[-1] - edges[0])]
        side = int(np.sign(np.median(rise))) if len(rise) else 0
        with np.errstate(invalid="ignore"):
            lo = np.where(np.isfinite(edges).all(0), edges.min(0), np.nan) - margin_px
            hi = np.where(np.isfinite(edges).all(0), edges.max(0), np.nan) + margin_px
        return Band(lo, hi, along_rows, side)


def apart(a: Band, b: Band, guard_px: float = 0.0) -> bool:
    """Whether no pixel could be in both bands (at least ``guard_px`` between them wherever
    both are); bands across different image directions are never apart."""
    if a.along_rows != b.along_rows:
        return False
    both = a.searched & b.searched
    if not both.any():
        return True
    gap = np.maximum(b.lo[both] - a.hi[both], a.lo[both] - b.hi[both])
    return bool((gap >= guard_px).all())


def exclusive(bands: Sequence[Band], guard_px: float = 0.0) -> list[Band]:
    """The bands less every pixel another of them also holds (within ``guard_px``): where
    two overlap, the lower keeps what lies below the upper's start and the upper what lies
    above the lower's end; a centre between gives no point. Bands across different image
    directions share no such order: where one's strip crosses another's, neither keeps it."""
    out = [replace(b, lo=b.lo.copy(), hi=b.hi.copy()) for b in bands]
    mid = [b.middle() for b in bands]
    for i, a in enumerate(bands):
        for j in range(i + 1, len(bands)):
            b = bands[j]
            if a.along_rows != b.along_rows:
                _cross_out(out[i], b)
                _cross_out(out[j], a)
                continue
            low, high = (i, j) if mid[i] <= mid[j] else (j, i)
            L, U = bands[low], bands[high]
            with np.errstate(invalid="ignore"):
                clash = L.searched & U.searched & (U.lo - L.hi < guard_px)
            out[low].hi[clash] = np.fmin(out[low].hi[clash], U.lo[clash] - guard_px)
            out[high].lo[clash] = np.fmax(out[high].lo[clash], L.hi[clash] + guard_px)
    for b in out:
        with np.errstate(invalid="ignore"):
            gone = ~(b.lo <= b.hi)
        b.lo[gone] = b.hi[gone] = np.nan
    return out


def _cross_out(band: Band, other: Band) -> None:
    """Remove from ``band`` the positions along it where ``other`` (across the other image
    direction) could also be: its strip's extent in ``band``'s along coordinate."""
    ok = other.searched
    if not ok.any():
        return
    lo, hi = np.nanmin(other.lo[ok]), np.nanmax(other.hi[ok])
    cols = np.arange(len(band.lo))
    hit = (cols >= np.floor(lo)) & (cols <= np.ceil(hi))
    band.lo[hit] = band.hi[hit] = np.nan


def stride(bands: Sequence[Band], guard_px: float = 0.0) -> int:
    """The least s such that every two lines s apart in ``bands`` (the lines of one pass,
    in order across it) lie apart: lines s apart may share an exposure."""
    n = len(bands)
    for s in range(1, n):
        if all(apart(bands[i], bands[i + s], guard_px) for i in range(n - s)):
            return s
    return max(n, 1)


def frames(n: int, s: int, skip: Sequence[int] = ()) -> list[list[int]]:
    """Lines 0 … n − 1 of a pass (less ``skip``) dealt into frames of lines ``s`` apart in
    the pass: frame j holds j, j + s, j + 2s, … (empty frames dropped)."""
    left = set(skip)
    out = [[i for i in range(j, n, s) if i not in left] for j in range(s)]
    return [f for f in out if f]


def survey(bands: Sequence[Band], guard_px: float = 0.0) -> list[list[int]]:
    """The frames that bound the part's heights before the lines are packed: the pass's
    first and last lines and every ⌈:func:`stride` / 3⌉ between (the bands given: those of
    the head's whole focus range), dealt into frames whose lines lie :func:`apart` — so they
    need no height range to tell their lines apart, and the table beside a part is seen."""
    n = len(bands)
    if n == 0:
        return []
    step = max((stride(bands, guard_px) + 2) // 3, 1)
    out: list[list[int]] = []
    for i in sorted(set(range(0, n, step)) | {n - 1}):
        for f in out:
            if all(apart(bands[i], bands[j], guard_px) for j in f):
                f.append(i)
                break
        else:
            out.append([i])
    return out
