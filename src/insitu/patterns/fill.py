"""Fills: outline offset (shapely buffer) and hatching (exact-spacing scan lines, even-odd).

Hatch lines are intersected with the contours' edges directly (a scan-line fill in the frame
rotated by the hatch angle), so spacing is exact and a 30 mm QR code at 0.04 mm takes
milliseconds. Segments that continue each other from line to line (each overlapping just the
other) form blocks marked back and forth; blocks, outlines and paths are then ordered
together with :func:`insitu.patterns.order.order_units`. Joined (``join``), a block's lines
are one polyline wherever a line ends within one spacing of the next one's start, straight
across the lines (along an edge that the outline marks anyway): one path, one laser-on and
one settling, instead of one per line (a marking program's "bow-shaped" fill).
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns.model import Pattern, contours_of
from insitu.patterns.order import is_closed, order_units, start_nearest

MAX_LINES = 200_000  # hatch lines per direction: 200 mm at 1 µm


def offset(pattern: Pattern, offset_mm: float) -> Pattern:
    """The filled region grown (``offset_mm`` > 0) or shrunk (< 0) by ``offset_mm`` mm, sharp
    corners kept (mitred joins); open paths are unchanged."""
    if offset_mm == 0 or not pattern.contours:
        return pattern
    g = shapely.buffer(pattern.to_shapely(), offset_mm, join_style="mitre", mitre_limit=4.0)
    return Pattern(tuple(contours_of(g)), pattern.paths, pattern.name, pattern.frame)


def hatch_segments(contours, spacing_mm: float, angle_deg: float = 0.0):
    """Scan-line fill of the even-odd region of ``contours`` ((N, 2) mm each).

    Lines run along ``angle_deg`` (CCW from +x), exactly ``spacing_mm`` apart, centred on the
    region (a region n·spacing tall gets n lines, the outer ones spacing/2 inside its edges).
    Returns (line index (S,) int, x0 (S,), x1 (S,), y (S,), rot (2, 2)): segment x0 < x1 at
    height y in the rotated frame; ``p_pattern = rot @ p_rotated``. Sorted by line, then x.
    """
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    empty = (np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros(0), rot)
    rings = [np.asarray(c, np.float64) @ rot for c in contours if len(c) >= 3]
    if not rings:
        return empty
    p0 = np.concatenate(rings)
    p1 = np.concatenate([np.roll(r, -1, axis=0) for r in rings])
    ymin, ymax = p0[:, 1].min(), p0[:, 1].max()
    n = max(1, math.ceil((ymax - ymin) / spacing_mm - 1e-9))
    if n > MAX_LINES:
        raise FormatError(f"hatch spacing {spacing_mm} mm is too fine for a region "
                          f"{ymax - ymin:.4g} mm across ({n} lines, at most {MAX_LINES})")
    base = 0.5 * (ymin + ymax) - 0.5 * (n - 1) * spacing_mm  # y of line 0
    lo, hi = np.minimum(p0[:, 1], p1[:, 1]), np.maximum(p0[:, 1], p1[:, 1])
    # edge crosses line k when lo <= y_k < hi (half-open: vertices count once, flats never)
    k0 = np.ceil((lo - base) / spacing_mm).astype(np.int64)
    k1 = np.ceil((hi - base) / spacing_mm).astype(np.int64)
    cnt = np.clip(k1 - k0, 0, None)
    if not cnt.sum():
        return empty
    e = np.repeat(np.arange(len(p0)), cnt)
    k = k0[e] + (np.arange(len(e)) - np.repeat(np.cumsum(cnt) - cnt, cnt))
    y = base + k * spacing_mm
    t = np.clip((y - p0[e, 1]) / (p1[e, 1] - p0[e, 1]), 0.0, 1.0)
    x = p0[e, 0] + t * (p1[e, 0] - p0[e, 0])
    o = np.lexsort((x, k))
    k, x, y = k[o], x[o], y[o]
    ks, xa, xb, ys = k[0::2], x[0::2], x[1::2], y[0::2]
    keep = xb - xa > 1e-9
    return ks[keep], xa[keep], xb[keep], ys[keep], rot


def _blocks(k: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> list[list[int]]:
    """Group segments into blocks: segment a on line j continues to b on line j+1 when they
    overlap and neither overlaps anything else there. Returns index lists in line order."""
    if not len(k):
        return []
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    ends = np.r_[starts[1:], len(k)]
    nxt = np.full(len(k), -1)
    has_prev = np.zeros(len(k), bool)
    for s0, e0, s1, e1 in zip(starts[:-1], ends[:-1], starts[1:], ends[1:]):
        if k[s1] != k[s0] + 1:
            continue
        axa, axb, bxa, bxb = xa[s0:e0], xb[s0:e0], xa[s1:e1], xb[s1:e1]
        alo = np.searchsorted(bxb, axa, "right")
        ahi = np.searchsorted(bxa, axb, "left")
        blo = np.searchsorted(axb, bxa, "right")
        bhi = np.searchsorted(axa, bxb, "left")
        one = np.flatnonzero(ahi - alo == 1)
        b = alo[one]
        good = bhi[b] - blo[b] == 1
        nxt[s0 + one[good]] = s1 + b[good]
        has_prev[s1 + b[good]] = True
    blocks = []
    for i in np.flatnonzero(~has_prev).tolist():
        chain = [i]
        while nxt[chain[-1]] >= 0:
            chain.append(int(nxt[chain[-1]]))
        blocks.append(chain)
    return blocks


def _hatch_units(contours, spacing, angle, bidirectional):
    """Hatch blocks as lists of (2, 2) segments in marking order (forward run)."""
    k, xa, xb, y, rot = hatch_segments(contours, spacing, angle)
    if not len(k):
        return []
    a = np.stack([xa, y], axis=1) @ rot.T
    b = np.stack([xb, y], axis=1) @ rot.T
    units = []
    for chain in _blocks(k, xa, xb):
        segs = []
        for j, s in enumerate(chain):
            forward = not bidirectional or j % 2 == 0
            segs.append(np.stack([a[s], b[s]]) if forward else np.stack([b[s], a[s]]))
        units.append(segs)
    return units


def joined(segs: list[np.ndarray], spacing_mm: float) -> list[np.ndarray]:
    """A block's hatch lines ((2, 2) each, in marking order) as polylines: one line runs on
    into the next where its end lies within ``spacing_mm`` of the next one's start (the step
    straight across the lines)."""
    out = [segs[0]]
    for s in segs[1:]:
        if np.linalg.norm(s[0] - out[-1][-1]) <= spacing_mm * (1 + 1e-6):
            out[-1] = np.vstack([out[-1], s])
        else:
            out.append(s)
    return out


def hatch(pattern: Pattern, spacing_mm: float, angle_deg: float = 0.0, cross: bool = False,
          bidirectional: bool = True, outline: bool = True, offset_mm: float = 0.0,
          start=(0.0, 0.0), join: bool = False) -> list[np.ndarray]:
    """The polylines to mark for ``pattern``, in marking order from ``start`` (mm).

    Filled regions get hatch lines along ``angle_deg`` exactly ``spacing_mm`` apart (and along
    angle + 90° too if ``cross``), back and forth (``bidirectional``) or all the same way; with
    ``outline`` their contours are marked too, as closed polylines (first == last).
    ``offset_mm`` grows (> 0) or shrinks (< 0) the region first (:func:`offset`); ``join``:
    a block's lines marked back and forth as one polyline (:func:`joined`). Open paths are
    marked as they are. Returns (N, 2) float64 mm arrays: outlines, hatch segments (2, 2; or
    joined) and paths, ordered together to cut the jump length.
    """
    if not (math.isfinite(spacing_mm) and spacing_mm > 0):
        raise FormatError(f"hatch spacing must be > 0 mm, got {spacing_mm}")
    if pattern.is_empty:
        raise FormatError(f"pattern {pattern.name or '(unnamed)'}: empty (nothing to mark)")
    p = offset(pattern, offset_mm)
    units: list[list[np.ndarray]] = []  # each unit: polylines marked one after another
    sym: list[bool] = []
    closed: list[bool] = []
    for angle in (angle_deg, angle_deg + 90.0) if cross else (angle_deg,):
        blocks = _hatch_units(p.contours, spacing_mm, angle, bidirectional)
        units += [joined(b, spacing_mm) for b in blocks] if join and bidirectional else blocks
        sym += [bidirectional or len(b) == 1 for b in blocks]
        closed += [False] * len(blocks)
    if outline:
        for c in p.contours:
            units.append([np.vstack([c, c[:1]])])
            sym.append(True)
            closed.append(True)
    for path in p.paths:
        units.append([np.array(path)])  # writeable copies, like the rest
        sym.append(True)
        closed.append(is_closed(path))
    if not units:
        raise FormatError(f"pattern {pattern.name}: nothing left to mark after an offset of "
                          f"{offset_mm} mm")
    entry = np.empty((len(units), 2, 2))
    exit_ = np.empty((len(units), 2, 2))
    for u, segs in enumerate(units):
        entry[u, 0], exit_[u, 0] = segs[0][0], segs[-1][-1]
        if sym[u]:
            entry[u, 1], exit_[u, 1] = segs[-1][-1], segs[0][0]
        else:  # unidirectional block run top-down: lines in reverse order, same direction
            entry[u, 1], exit_[u, 1] = segs[-1][0], segs[0][-1]
    order, var = order_units(entry, exit_, sym, start)
    out: list[np.ndarray] = []
    cur = np.asarray(start, np.float64)
    for u, v in zip(order, var):
        segs = units[u]
        if v:
            segs = [s[::-1] for s in segs[::-1]] if sym[u] else segs[::-1]
        if closed[u]:
            segs = [start_nearest(segs[0], cur)]
        out.extend(segs)
        cur = segs[-1][-1]
    return out
