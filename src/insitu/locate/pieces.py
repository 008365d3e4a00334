"""The straight and round pieces of an outline fitted to edge points (a scan reference's, from
its room-light frame or its lines: :mod:`insitu.locate.outline_fit`).

Edge points are chained (:data:`LINK_MM` apart, their normals within :data:`TURN_DEG`, on one
level), and each chain is fitted with a line or else a circle; a chain neither fits within
:data:`FIT_MM` is split where it leaves its chord furthest (a corner). The fits are robust
(iteratively reweighted, Tukey's biweight on the residuals' median spread: Huber & Ronchetti,
*Robust Statistics*, ch. 7): a few stray edge points — a shadow's step, a corner's rounding —
would otherwise turn a 20 mm side by ±0.05 mm end to end. Each piece carries its own 1σ:
of its offset across it and of its turn (± at its ends), from its residuals' spread over the
stretches along it that vary independently (:data:`CORRELATED_MM`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

LINK_MM = 1.0
TURN_DEG = 30.0
FIT_MM = 0.1
"""A line or circle fits a chain of edge points when they scatter less than this about it
(the frame's edges scatter 0.02–0.06 mm about a part's true outline at binning 2)."""
MIN_PIECE_MM = 3.0
DENSE = 0.25
"""A piece needs edge points along this share of its length: a few points found here and
there are no edge."""
MERGE_DEG = 2.0
CUT_SHARE = 0.1
"""A chain fits a line or circle when its biweight cuts at most this share of its points (a
corner's other side would be half of them)."""
LOOSE = (0.25, 0.15)
"""(share cut, rms mm) within which a chain gives a piece to look along again: edge points
found about a rough outline scatter more than those found about a fitted edge (a scan's lines
1 mm apart: the rough outline 1.1 mm in to 0.4 mm out, 14–19 % of a side's points 0.25–0.7
mm off, from the wall's foot or the top's texture)."""
TUKEY = 4.685
"""Tukey's biweight cut, in robust σ of the residuals (95 % efficient on normal scatter)."""
ROBUST_STEPS = 8
CORRELATED_MM = 2.0
"""Edge points closer than this along an edge share their error (the light and the pixel
grid move a frame's edge over millimetres: binned medians of 100 points along a side
scatter ±0.02 mm): a piece's σ counts one independent residual a stretch this long."""


@dataclass(frozen=True)
class Piece:
    """One fitted edge: ``kind`` "line" (``centre`` a point on it, ``axis`` its unit
    direction) or "circle" (``centre``, ``radius_mm``); ``outward`` ±1: the side the part's
    surface drops to (+: the line's left normal, the circle's outside); ``extent`` along it
    (mm along the axis from the centre; a circle's angles, rad); ``length_mm``; ``rms_mm`` of
    the edge points about it (``points`` of them) at height ``z_mm`` (their median), from the
    ``source`` "frame" or, where it showed none, the "scan"; ``sigma_mm``: 1σ of its offset
    across it and ``tilt_mm``: of its turn, ± at its ends, from its fit; ``scan``: the
    scan's edge samples crossing it, from ``directions`` line directions (2: crossed), and
    ``offset_mm`` how far outward of where they put its edge it lies (nan: not measured);
    ``view_deg``: how obliquely the camera sees the top just inside it (the angle between
    the top's normal and the ray to the camera)."""

    kind: str
    centre: np.ndarray
    axis: np.ndarray | None
    radius_mm: float
    outward: float
    extent: tuple[float, float]
    length_mm: float
    rms_mm: float
    points: int
    z_mm: float
    source: str = "frame"
    sigma_mm: float = 0.0
    tilt_mm: float = 0.0
    scan: int = 0
    directions: int = 0
    offset_mm: float = float("nan")
    view_deg: float = 0.0

    def sample(self, spacing_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """(points (K, 2), outward normals (K, 2)) every ``spacing_mm`` along it."""
        n = max(2, int(np.ceil(self.length_mm / spacing_mm)) + 1)
        s = np.linspace(*self.extent, n)
        if self.kind == "line":
            left = np.array([-self.axis[1], self.axis[0]])
            return self.centre + s[:, None] * self.axis, np.tile(self.outward * left, (n, 1))
        radial = np.column_stack([np.cos(s), np.sin(s)])
        return self.centre + self.radius_mm * radial, self.outward * radial

    def moved(self, outward_mm: float) -> Piece:
        """The piece moved ``outward_mm`` along its outward normal."""
        if self.kind == "line":
            left = np.array([-self.axis[1], self.axis[0]])
            return replace(self, centre=self.centre + outward_mm * self.outward * left)
        return replace(self, radius_mm=self.radius_mm + outward_mm * self.outward)

    def distance(self, xy: np.ndarray) -> np.ndarray:
        """(K,) signed distance, mm, of points (K, 2) from it, outward positive."""
        if self.kind == "line":
            left = np.array([-self.axis[1], self.axis[0]])
            return self.outward * ((xy - self.centre) @ left)
        return self.outward * (np.linalg.norm(xy - self.centre, axis=1) - self.radius_mm)


def fitted(xy: np.ndarray, normals: np.ndarray, z: np.ndarray, spacing_mm: float,
           source: str = "frame", loose: bool = False) -> list[Piece]:
    """The pieces fitted to edge points ``xy`` (K, 2) (outward ``normals`` (K, 2), heights
    ``z`` (K,)) found about ``spacing_mm`` apart along their edges; ``loose``: within
    :data:`LOOSE` (where to look again for an edge, not the edge)."""
    return merged([piece for chain in chains(xy, normals, z) for piece in
                   pieces(xy[chain], normals[chain], z[chain], spacing_mm, source,
                          loose=loose)])


def chains(xy: np.ndarray, normals: np.ndarray, z: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the edge points chained ``LINK_MM`` apart, normals within
    ``TURN_DEG``, heights within 0.5 mm."""
    pairs = cKDTree(xy).query_pairs(LINK_MM, output_type="ndarray")
    if len(pairs):
        a, b = pairs.T
        pairs = pairs[(np.einsum("ij,ij->i", normals[a], normals[b])
                       > np.cos(np.radians(TURN_DEG))) & (np.abs(z[a] - z[b]) < 0.5)]
    graph = coo_matrix((np.ones(len(pairs)), tuple(pairs.T)) if len(pairs) else
                       ([], ([], [])), shape=(len(xy), len(xy)))
    label = connected_components(graph, directed=False)[1]
    return [np.flatnonzero(label == k) for k in np.unique(label)]


def pieces(xy: np.ndarray, normals: np.ndarray, z: np.ndarray, spacing_mm: float,
           source: str, depth: int = 0, loose: bool = False) -> list[Piece]:
    """A line, else a circle fitted robustly to a chain's points ``xy`` (K, 2) (outward
    ``normals`` (K, 2), heights ``z`` (K,), found ``spacing_mm`` apart along it); split at
    its corner when neither fits (``loose``: within :data:`LOOSE`). None from a chain
    shorter than ``MIN_PIECE_MM`` or with fewer points than ``DENSE`` of its length's."""
    if len(xy) < 5:
        return []
    m, axis, r_line, w = robust_line(xy)
    t = (xy - m) @ axis
    if np.ptp(t) < MIN_PIECE_MM or len(xy) < DENSE * np.ptp(t) / spacing_mm:
        return []
    left = np.array([-axis[1], axis[0]])
    if fits(r_line, w, loose):
        sign = 1.0 if np.mean(normals @ left) > 0 else -1.0
        length = float(np.ptp(t[w > 0])) if (w > 0).sum() > 1 else float(np.ptp(t))
        sigma, tilt = piece_sigma(r_line, w, length)
        return [Piece("line", m, axis, np.inf, sign, (float(t.min()), float(t.max())),
                      float(np.ptp(t)), rms(r_line[w > 0]), len(xy), float(np.median(z)), source,
                      sigma, tilt)]
    c, radius, r_circle, wc = robust_circle(xy)
    if np.isfinite(radius) and fits(r_circle, wc, loose):
        radial = (xy - c) / np.maximum(np.linalg.norm(xy - c, axis=1, keepdims=True), 1e-12)
        ang = np.unwrap(np.arctan2(radial[:, 1], radial[:, 0])[np.argsort(t)])
        span = (float(ang.min()), float(ang.max()))
        if np.ptp(ang) > 1.9 * np.pi:                     # closed: the whole circle
            span = (0.0, 2 * np.pi)
        sign = 1.0 if np.mean(np.einsum("ij,ij->i", normals, radial)) > 0 else -1.0
        length = radius * (span[1] - span[0])
        sigma, tilt = piece_sigma(r_circle, wc, length)
        return [Piece("circle", c, None, radius, sign, span, length, rms(r_circle[wc > 0]), len(xy),
                      float(np.median(z)), source, sigma, tilt)]
    if depth > 6:
        return []
    corner = np.argmax(np.abs(r_line - np.interp(t, [t.min(), t.max()],
                                                 [r_line[np.argmin(t)], r_line[np.argmax(t)]])))
    cut = t <= t[corner]
    return (pieces(xy[cut], normals[cut], z[cut], spacing_mm, source, depth + 1, loose)
            + pieces(xy[~cut], normals[~cut], z[~cut], spacing_mm, source, depth + 1, loose))


def robust_line(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(a point on it (2,), its unit direction (2,), residuals (K,) across it, the points'
    weights (K,), 0 for those cut) of the line through ``xy`` (K, 2), total least squares
    reweighted by Tukey's biweight."""
    w = np.ones(len(xy))
    for _ in range(ROBUST_STEPS):
        m = (w[:, None] * xy).sum(axis=0) / w.sum()
        d = xy - m
        axis = np.linalg.eigh((w[:, None] * d).T @ d)[1][:, -1]
        r = d @ np.array([-axis[1], axis[0]])
        w = _biweight(r)
    return m, axis, r, w


def robust_circle(xy: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """(centre (2,), radius, residuals (K,) outward, weights (K,)) of the circle through
    ``xy`` (K, 2): Kåsa's algebraic fit reweighted by Tukey's biweight."""
    w = np.ones(len(xy))
    A = np.column_stack([xy, np.ones(len(xy))])
    b = (xy ** 2).sum(axis=1)
    c, radius, r = np.zeros(2), float("inf"), np.zeros(len(xy))
    for _ in range(ROBUST_STEPS):
        sw = np.sqrt(w)
        sol = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)[0]
        c = sol[:2] / 2
        r2 = sol[2] + c @ c
        if r2 <= 0:
            return c, float("inf"), np.full(len(xy), np.inf), w
        radius = float(np.sqrt(r2))
        r = np.linalg.norm(xy - c, axis=1) - radius
        w = _biweight(r)
    return c, radius, r, w


def _biweight(r: np.ndarray) -> np.ndarray:
    """Tukey's biweight of residuals ``r`` on their median absolute deviation (at least
    0.002 mm: an exact fit)."""
    s = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 0.002)
    u = r / (TUKEY * s)
    return np.where(np.abs(u) < 1, (1 - u ** 2) ** 2, 0.0)


def piece_sigma(r: np.ndarray, w: np.ndarray, length_mm: float) -> tuple[float, float]:
    """(1σ of a piece's offset across it, of its turn ± at its ends), mm, from its residuals
    ``r`` (K,) and weights ``w`` (K,) over ``length_mm``: the weighted spread over one
    independent residual every ``CORRELATED_MM`` (the slope's over a uniform spread of
    them: √3 times the offset's at the ends); a piece shorter than two such stretches counts
    its length's share of them, one at least (a few millimetres of edge are one stretch
    whose error its own scatter does not show)."""
    spread = float(np.sqrt((w * r ** 2).sum() / max(w.sum(), 1e-12)))
    n = max(1.0, length_mm / CORRELATED_MM)
    return spread / np.sqrt(n), spread * np.sqrt(3.0 / n)


def merged(found: list[Piece]) -> list[Piece]:
    """The lines that continue one another (within ``MERGE_DEG`` and ``FIT_MM`` of each
    other, on one level) as one (their points' fits pooled, their extents joined, their σ
    combined as independent)."""
    lines = sorted((p for p in found if p.kind == "line"), key=lambda p: -p.length_mm)
    out = [p for p in found if p.kind != "line"]
    for p in lines:
        for k, q in enumerate(out):
            if (q.kind == "line" and q.source == p.source and abs(q.z_mm - p.z_mm) < 0.5
                    and q.outward * p.outward * (q.axis @ p.axis) > np.cos(np.radians(MERGE_DEG))
                    and abs(q.distance(p.centre[None])[0]) < FIT_MM):
                ends = np.concatenate([[(p.centre + s * p.axis - q.centre) @ q.axis
                                        for s in p.extent], q.extent])
                w = p.points + q.points
                out[k] = replace(q, extent=(float(ends.min()), float(ends.max())),
                                 length_mm=float(np.ptp(ends)), points=w,
                                 rms_mm=float(np.hypot(q.rms_mm * np.sqrt(q.points / w),
                                                       p.rms_mm * np.sqrt(p.points / w))),
                                 sigma_mm=_pooled(q.sigma_mm, p.sigma_mm),
                                 tilt_mm=_pooled(q.tilt_mm, p.tilt_mm))
                break
        else:
            out.append(p)
    return out


def _pooled(a: float, b: float) -> float:
    """1σ of two independent estimates of one value pooled by their inverse variances."""
    return float(1.0 / np.sqrt(1.0 / max(a, 1e-9) ** 2 + 1.0 / max(b, 1e-9) ** 2))


def fits(r: np.ndarray, w: np.ndarray, loose: bool = False) -> bool:
    """Whether a line or circle fits points with residuals ``r`` (K,) and biweights ``w``
    (K,): at most ``CUT_SHARE`` of them cut, the rest within ``FIT_MM`` (rms); ``loose``:
    within :data:`LOOSE`."""
    kept = w > 0
    cut, fit = LOOSE if loose else (CUT_SHARE, FIT_MM)
    return bool(kept.mean() >= 1 - cut and rms(r[kept]) <= fit)


def rms(r: np.ndarray) -> float:
    """RMS of residuals after the 1 % furthest are left out (a stray edge point)."""
    a = np.sort(np.abs(r - np.median(r)))
    return float(np.sqrt(np.mean(a[: max(1, int(np.ceil(0.99 * len(a))))] ** 2)))
