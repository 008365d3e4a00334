"""A scan reference's outline as clean as a mesh's: its edges found in the reference's own
room-light frame, fitted with straight lines and circles, checked against the crossed scan.

A first scan of the part as its reference gives a height image whose edges are where its
lines ended (a little inside, along each line) smoothed by the splat: good enough to find the
part, not to place it to 0.05 mm. Its room-light frame (the same camera, laser off) shows the
same edges whole. So: the splat's rough outline (:func:`insitu.locate.image_edges.outline`) is
projected into the frame (the reference's frame is the scan's world frame); along each
point's normal the steepest grey step within ``SEARCH_PX`` is its edge, cut at the point's
height (as :func:`insitu.locate.image_edges.align_image` finds a later part's). The edge
points, chained (:data:`LINK_MM` apart, their normals within :data:`TURN_DEG`), are fitted
piece by piece with a line or else a circle (least squares, Kåsa's algebraic circle), a chain
neither fits within :data:`FIT_MM` being split where it leaves its chord furthest (a corner);
pieces shorter than :data:`MIN_PIECE_MM` (rounded corners) are left out. The pieces, sampled
every ``SPACING_MM``, are the reference's outline; :func:`stamp` redraws the height image's
edges on them, so the scan lines' edge step (:mod:`insitu.locate.edge_align`) finds them there.

The crossed scan checks each piece: the scan's edge samples by it (lines crossing it) and how
far inside it they end along their lines (the inset, about the same for every edge when the
outline is right), from how many directions (two: crossed).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from insitu.geometry.camera import CameraModel
from insitu.locate.edge_align import MIN_COS, EdgeSamples
from insitu.locate.height_image import HeightImage, sample
from insitu.locate.image_edges import (
    SPACING_MM,
    STEP_PX,
    WALL_PX,
    Outline,
    edge_heights,
    edge_points,
    frame_of,
    outline,
    visible,
    wall_px,
)
from insitu.locate.uncertainty import SCAN_REFERENCE_MM

SEARCH_PX = 6.0
"""How far from the splat's rough edge the frame's is looked for (its edges lie up to a few
tenths of a mm off)."""
LINK_MM = 1.0
TURN_DEG = 30.0
FIT_MM = 0.1
"""A line or circle fits a chain of edge points when they scatter less than this about it
(the frame's edges scatter 0.02–0.06 mm about a part's true outline at binning 2)."""
MIN_CHECK = 3
DEEP_MM = (0.3, 1.2)
"""A splat's top is carried to its edges from this band inside them (:func:`top_heights`):
its last few tenths of a mm lie low (the lines end short of an edge, the splat's kernel
reaches over it; 1.1–1.6 mm low at 0.2 mm in), and an edge point cut at too low a height
lies outward along the camera's ray (0.46 mm a mm of height at the rig's 25° view)."""
ROUGH_MM = 0.5
"""A frame's piece must run this close to the splat's rough outline (whose edges lie up to
0.3 mm out: the table beside a wall is in shadow)."""
MIN_PIECE_MM = 3.0
DENSE = 0.25
"""A piece needs edge points along this share of its length (the outline's points are
``SPACING_MM`` apart): a few points found here and there are no edge."""
MERGE_DEG = 2.0
NEAR_MM = 0.5
SCAN_SPACING_MM = 0.5
"""About how far apart along an edge a crossed scan's lines end on it."""
"""Scan edge samples this close to a piece (across it) check it."""


@dataclass(frozen=True)
class Piece:
    """One fitted edge: ``kind`` "line" (``centre`` a point on it, ``axis`` its unit
    direction) or "circle" (``centre``, ``radius_mm``); ``outward`` ±1: the side the part's
    surface drops to (+: the line's left normal, the circle's outside); ``length_mm``;
    ``rms_mm`` of the edge points about it (``points`` of them) at height ``z_mm`` (their
    median), from the ``source`` "frame" or, where it showed none, the "scan"; ``scan``: the
    scan's
    edge samples crossing it, from ``directions`` line directions (2: crossed), ending
    ``inset_mm`` (median) inside it along their lines (nan: none)."""

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
    scan: int = 0
    directions: int = 0
    offset_mm: float = float("nan")

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


@dataclass(frozen=True)
class OutlineFit:
    """The reference's fitted ``outline`` (part frame; as its frame shows it, for a later
    frame's edges), its ``pieces``, ``covered``: the share of the rough outline's points (the
    splat's edges) whose edge the frame showed, ``inset_mm``: how far inside their edges the
    scan's lines end (nan: not measured), and ``anchored``: the outline where the scan's lines
    put it (each piece moved by its ``offset_mm``, for the scan lines' edge step)."""

    outline: Outline
    pieces: tuple[Piece, ...]
    covered: float
    inset_mm: float
    anchored: Outline

    def length_mm(self, crossed: bool = False) -> float:
        """The pieces' length (``crossed``: only those the scan crosses from two ways)."""
        return float(sum(p.length_mm for p in self.pieces if not crossed or p.directions > 1))


def fit_outline(heights: HeightImage, image: np.ndarray, camera: CameraModel,
                scan: EdgeSamples | None = None) -> OutlineFit | str:
    """The outline of the part a scan ``heights`` (its splat, part frame = world) shows, from
    ``image`` (H, W), ``camera``'s room-light frame of it as scanned, checked by the scan's
    edge samples ``scan`` (world frame; None: not checked). Why not, as a sentence, when the
    frame is not the camera's or shows too little of the outline."""
    if image.shape[:2] != (camera.height, camera.width):
        return (f"the frame is {image.shape[1]}×{image.shape[0]} px, the camera "
                f"{camera.width}×{camera.height}")
    rough = outline(heights)
    rough = replace(rough, points=np.column_stack([rough.points[:, :2], top_heights(
        heights, rough.points[:, :2], rough.normals)]))
    width = wall_px(rough, camera, 0.0, np.zeros(3))
    seen = visible(heights, rough, camera, 0.0, np.zeros(3)) & ~((width > 0) & (width < WALL_PX))
    if seen.sum() < 50:
        return f"{seen.sum()} of the outline's {len(rough.points)} points in the camera's view"
    p, n = rough.points[seen], rough.normals[seen]
    offs = np.arange(-SEARCH_PX, SEARCH_PX + 1e-9, STEP_PX)
    found, e, _ = edge_points(frame_of(image), camera, p, n, offs,
                              np.where(width[seen] > 0, width[seen] / 2, np.inf))
    pieces = [q for q in _fitted(e[found], n[found], p[found, 2], SPACING_MM)
              if _near_rough(q, rough)]
    inset = float("nan")
    if scan is not None and len(scan):
        pieces, inset = _anchored(pieces, scan)
        pieces += _from_scan(pieces, rough, scan, inset)
    if not pieces:
        return (f"no straight or round edge fitted to the {found.sum()} edge points the frame "
                f"shows of the outline's {len(rough.points)}")
    known = [q.offset_mm for q in pieces if np.isfinite(q.offset_mm)]
    shift = float(np.median(known)) if known else 0.0
    return OutlineFit(_sampled(heights, pieces), tuple(pieces),
                      float(found.sum() / len(rough.points)), inset,
                      _sampled(heights, [q.moved(-q.offset_mm if np.isfinite(q.offset_mm)
                                                 else -shift) for q in pieces]))


def _sampled(heights: HeightImage, pieces: list[Piece]) -> Outline:
    """The pieces sampled every ``SPACING_MM``, with the heights of ``heights`` each side (the
    top's from ``DEEP_MM`` inside) and each piece's 1σ (checked by the crossed scan's lines
    or not: :data:`insitu.locate.uncertainty.SCAN_REFERENCE_MM`)."""
    pts, nrm = (np.concatenate(a) for a in zip(*(q.sample(SPACING_MM) for q in pieces)))
    below = edge_heights(heights, pts, nrm)[1]
    sigma = np.concatenate([np.full(len(q.sample(SPACING_MM)[0]), SCAN_REFERENCE_MM[
        "checked" if q.scan >= MIN_CHECK and np.isfinite(q.offset_mm) else "fitted"])
        for q in pieces])
    return Outline(np.column_stack([pts, top_heights(heights, pts, nrm)]), nrm, below, sigma)


def top_heights(heights: HeightImage, edge: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(K,) mm: the top's height at each edge point ``edge`` (K, 2) of a splat ``heights``, a
    line through its heights every 0.1 mm of ``DEEP_MM`` inside along the outward normal
    ``n`` (K, 2) carried on to the edge — through the upper half of them (a sparse splat
    falls between its lines)."""
    depth = np.arange(DEEP_MM[0], DEEP_MM[1] + 1e-9, 0.1)
    q = edge[:, None, :] - depth[None, :, None] * n[:, None, :]
    z = sample([heights.z], *heights.pixel(q.reshape(-1, 2)))[0].reshape(len(edge), -1)
    upper = z >= np.median(z, axis=1, keepdims=True)
    m = upper.sum(axis=1)
    d_mean = (upper * depth).sum(axis=1) / m
    z_mean = (upper * z).sum(axis=1) / m
    dd = np.where(upper, depth - d_mean[:, None], 0.0)
    slope = (dd * (z - z_mean[:, None])).sum(axis=1) / np.maximum((dd ** 2).sum(axis=1), 1e-12)
    return z_mean - slope * d_mean


def _fitted(xy: np.ndarray, normals: np.ndarray, z: np.ndarray, spacing_mm: float,
            source: str = "frame") -> list[Piece]:
    """The pieces fitted to edge points ``xy`` (K, 2) (outward ``normals`` (K, 2), heights
    ``z`` (K,)) found about ``spacing_mm`` apart along their edges."""
    return _merged([piece for chain in _chains(xy, normals, z) for piece in
                    _pieces(xy[chain], normals[chain], z[chain], spacing_mm, source)])


def _near_rough(piece: Piece, rough: Outline) -> bool:
    """Whether ``piece`` runs along the rough outline (within ``ROUGH_MM``, median): not the
    foot of a wall the camera sees, or a shadow's edge."""
    pts, _ = piece.sample(SPACING_MM)
    return bool(np.median(cKDTree(rough.points[:, :2]).query(pts)[0]) < ROUGH_MM)


def _from_scan(pieces: list[Piece], rough: Outline, scan: EdgeSamples,
               inset_mm: float) -> list[Piece]:
    """Pieces where the frame showed none (a wall the camera sees edge-on, two tops alike):
    the scan's edge samples there, each moved on along its line by ``inset_mm`` (0 when not
    measured), fitted alike."""
    xy = scan.points[:, :2] + np.nan_to_num(inset_mm) * scan.dirs
    far = np.ones(len(xy), bool)
    for q in pieces:
        far &= np.abs(q.distance(xy)) > NEAR_MM
    k = cKDTree(rough.points[:, :2]).query(xy)[1]
    nu = np.einsum("ij,ij->i", scan.dirs, rough.normals[k])
    keep = far & (nu > 0.3)
    return [replace(q, offset_mm=0.0) for q in
            _fitted(xy[keep], rough.normals[k][keep], scan.points[keep, 2], SCAN_SPACING_MM,
                    "scan")]


def _chains(xy: np.ndarray, normals: np.ndarray, z: np.ndarray) -> list[np.ndarray]:
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


def _pieces(xy: np.ndarray, normals: np.ndarray, z: np.ndarray, spacing_mm: float,
            source: str, depth: int = 0) -> list[Piece]:
    """A line, else a circle fitted to a chain's points ``xy`` (K, 2) (outward ``normals``
    (K, 2), heights ``z`` (K,), found ``spacing_mm`` apart along it); split at its corner
    when neither fits. None from a chain shorter than ``MIN_PIECE_MM`` or with fewer points
    than ``DENSE`` of its length's."""
    if len(xy) < 5:
        return []
    m = xy.mean(axis=0)
    axis = np.linalg.svd(xy - m, full_matrices=False)[2][0]
    t = (xy - m) @ axis
    if np.ptp(t) < MIN_PIECE_MM or len(xy) < DENSE * np.ptp(t) / spacing_mm:
        return []
    left = np.array([-axis[1], axis[0]])
    r_line = (xy - m) @ left
    if _rms(r_line) <= FIT_MM:
        sign = 1.0 if np.mean(normals @ left) > 0 else -1.0
        return [Piece("line", m, axis, np.inf, sign, (float(t.min()), float(t.max())),
                      float(np.ptp(t)), _rms(r_line), len(xy), float(np.median(z)), source)]
    c, radius = _circle(xy)
    radial = (xy - c) / np.maximum(np.linalg.norm(xy - c, axis=1, keepdims=True), 1e-12)
    r_circle = np.linalg.norm(xy - c, axis=1) - radius
    if np.isfinite(radius) and _rms(r_circle) <= FIT_MM:
        ang = np.unwrap(np.arctan2(radial[:, 1], radial[:, 0])[np.argsort(t)])
        span = (float(ang.min()), float(ang.max()))
        if np.ptp(ang) > 1.9 * np.pi:                     # closed: the whole circle
            span = (0.0, 2 * np.pi)
        sign = 1.0 if np.mean(np.einsum("ij,ij->i", normals, radial)) > 0 else -1.0
        return [Piece("circle", c, None, radius, sign, span, radius * (span[1] - span[0]),
                      _rms(r_circle), len(xy), float(np.median(z)), source)]
    if depth > 6:
        return []
    corner = np.argmax(np.abs(r_line - np.interp(t, [t.min(), t.max()],
                                                 [r_line[np.argmin(t)], r_line[np.argmax(t)]])))
    cut = t <= t[corner]
    return (_pieces(xy[cut], normals[cut], z[cut], spacing_mm, source, depth + 1)
            + _pieces(xy[~cut], normals[~cut], z[~cut], spacing_mm, source, depth + 1))


def _merged(pieces: list[Piece]) -> list[Piece]:
    """The lines that continue one another (within ``MERGE_DEG`` and ``FIT_MM`` of each
    other, on one level) as one (their points' fits pooled, their extents joined)."""
    lines = sorted((p for p in pieces if p.kind == "line"), key=lambda p: -p.length_mm)
    out = [p for p in pieces if p.kind != "line"]
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
                                                       p.rms_mm * np.sqrt(p.points / w))))
                break
        else:
            out.append(p)
    return out


def _circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Kåsa's least-squares circle through (K, 2) points: (centre (2,), radius)."""
    A = np.column_stack([xy, np.ones(len(xy))])
    b = (xy ** 2).sum(axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = sol[:2] / 2
    r2 = sol[2] + c @ c
    return c, float(np.sqrt(r2)) if r2 > 0 else float("inf")


def _rms(r: np.ndarray) -> float:
    """RMS of residuals after the 1 % furthest are left out (a stray edge point)."""
    a = np.sort(np.abs(r - np.median(r)))
    return float(np.sqrt(np.mean(a[: max(1, int(np.ceil(0.99 * len(a))))] ** 2)))


def _anchored(pieces: list[Piece], scan: EdgeSamples) -> tuple[list[Piece], float]:
    """(``pieces`` with the scan's edge samples crossing each — how many, from how many line
    directions, and how far outward of where they put its edge the frame's piece lies —,
    the inset the lines end at along themselves, mm; nan: not measured). Each sample i by
    piece k lies d_i = o_k − b·ν_i across it (outward): o_k the piece's offset, b the one
    inset of every line, ν_i its line's cosine to the piece's normal; least squares over the
    pieces with ``MIN_CHECK`` samples (b needs lines crossing a piece at two angles; else
    nan and the offsets keep the inset)."""
    xy, u = scan.points[:, :2], scan.dirs
    rows = []
    for k, piece in enumerate(pieces):
        d = piece.distance(xy)
        pts, nrm = piece.sample(SPACING_MM)
        foot = cKDTree(pts).query(xy)[1]
        nu = np.einsum("ij,ij->i", u, nrm[foot])
        near = (np.abs(d) < NEAR_MM) & (nu > MIN_COS) & (
            np.linalg.norm(xy - pts[foot] + d[:, None] * nrm[foot], axis=1) < 2 * SPACING_MM)
        ang = np.degrees(np.arctan2(u[near, 1], u[near, 0])) % 180.0
        dirs = 1 + int(len(ang) > 0 and np.any(np.abs((ang - ang[0] + 90.0) % 180.0 - 90.0)
                                                > 20.0))
        pieces[k] = replace(piece, scan=int(near.sum()), directions=dirs * bool(near.any()))
        if near.sum() >= MIN_CHECK:
            rows.append((k, d[near], nu[near]))
    if not rows:
        return pieces, float("nan")
    K = len(rows)
    A = np.zeros((sum(len(d) for _, d, _ in rows), K + 1))
    y = np.concatenate([d for _, d, _ in rows])
    at = 0
    for j, (_, d, nu) in enumerate(rows):
        A[at:at + len(d), j], A[at:at + len(d), K] = 1.0, -nu
        at += len(d)
    spread = np.concatenate([nu - nu.mean() for _, _, nu in rows])
    if np.sqrt(np.mean(spread ** 2)) < 0.05:            # one angle a piece: b not seen
        A, b = A[:, :K], float("nan")
    x = np.linalg.lstsq(A, y, rcond=None)[0]
    b = float(x[K]) if A.shape[1] > K else float("nan")
    for j, (k, _, _) in enumerate(rows):
        pieces[k] = replace(pieces[k], offset_mm=float(x[j]))
    return pieces, b


def stamp(heights: HeightImage, edges: Outline, band_mm: float = 0.5) -> HeightImage:
    """``heights`` with its edges redrawn on ``edges`` (a fitted outline): each pixel within
    ``band_mm`` across an outline point, beside it (not past its piece's end), takes the top's
    height on the inside and the surface's beyond, the pixel the edge crosses their mix by
    area."""
    h, w = heights.z.shape
    rows, cols = np.mgrid[0:h, 0:w]
    xy = np.column_stack([heights.x0_mm + cols.ravel() * heights.px_mm,
                          heights.y0_mm + rows.ravel() * heights.px_mm])
    dist, k = cKDTree(edges.points[:, :2]).query(xy, distance_upper_bound=band_mm)
    near = np.isfinite(dist)
    k = k[near]
    off = xy[near] - edges.points[k, :2]
    n = edges.normals[k]
    across = np.einsum("ij,ij->i", off, n)
    beside = np.abs(off[:, 0] * n[:, 1] - off[:, 1] * n[:, 0]) <= SPACING_MM
    inside = np.clip(0.5 - across / heights.px_mm, 0.0, 1.0)
    z = heights.z.ravel().copy()
    idx = np.flatnonzero(near)[beside]
    z[idx] = (edges.below[k] + inside * (edges.points[k, 2] - edges.below[k]))[beside]
    return HeightImage(z.reshape(h, w).astype(np.float32), heights.x0_mm, heights.y0_mm,
                       heights.px_mm)
