"""A scan reference's outline as clean as a mesh's: its edges found in the reference's own
room-light frame, fitted with straight lines and circles, checked against the crossed scan.

A first scan of the part as its reference gives a height image whose edges are where its
lines ended (a little inside, along each line) smoothed by the splat: good enough to find the
part, not to place it to 0.05 mm. Its room-light frame (the same camera, laser off) shows the
same edges whole. So the frame's edges about the splat's rough outline
(:func:`insitu.locate.image_edges.outline`, projected into the frame: the reference's frame is
the scan's world frame) are fitted piece by piece with lines and circles
(:mod:`insitu.locate.pieces`), looked for again along each
(:mod:`insitu.locate.frame_pieces`). The pieces, sampled every ``SPACING_MM``, are the
reference's outline; :func:`stamp` redraws the height image's edges on them, so the scan
lines' edge step (:mod:`insitu.locate.edge_align`) finds them there.

The crossed scan checks each piece: the scan's edge samples by it (lines crossing it) and how
far inside it they end along their lines (the inset, about the same for every edge when the
outline is right), from how many directions (two: crossed).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from insitu.geometry.camera import CameraModel
from insitu.locate.edge_align import MIN_COS, EdgeSamples
from insitu.locate.frame_pieces import frame_pieces
from insitu.locate.height_image import HeightImage, sample
from insitu.locate.image_edges import SPACING_MM, Outline, edge_heights, frame_of, outline
from insitu.locate.pieces import Piece, fitted
from insitu.locate.uncertainty import reference_floor

MIN_CHECK = 3
GRAZING_DEG = 45.0
"""A piece whose top the camera sees this obliquely or more (:func:`view_deg`) counts as
not checked by the scan's lines: the arc's far end, its top falling 28° away from a camera
25° off the vertical (53°), lies 0.052–0.067 mm out in its frame and so do the few lines'
ends that cross it there (6–9 on 39 mm); its near end (3°) +0.016, the flat tops' (25°)
within 0.03."""
DEEP_MM = (0.3, 1.2)
"""A top is carried to its edges from this band inside them (:func:`top_heights`,
:func:`scan_heights`): a splat's last few tenths of a mm lie low (the lines end short of an
edge, the splat's kernel reaches over it; 1.1–1.6 mm low at 0.2 mm in), and an edge point cut
at too low a height lies outward along the camera's ray (0.46 mm a mm of height at the rig's
25° view)."""
NEAREST_MM = 0.15
"""A scan point within this of a place inside an edge gives the top's height there."""
NEAR_MM = 0.5
"""Scan edge samples this close to a piece (across it) check it."""
SCAN_SPACING_MM = 0.5
"""About how far apart along an edge a crossed scan's lines end on it."""
LINE_ENDS_MIN = (10.0, 40)
"""A piece fitted to the scan's line ends this long (mm) from this many of them at least is
held to their bias (:data:`insitu.locate.uncertainty.LINE_ENDS_MM`, measured on pieces
13–38 mm long from 58 line ends or more); a shorter one, like a frame's piece not
checked."""


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
                scan: EdgeSamples | None = None, part: np.ndarray | None = None
                ) -> OutlineFit | str:
    """The outline of the part a scan ``heights`` (its splat, part frame = world) shows, from
    ``image`` (H, W), ``camera``'s room-light frame of it as scanned, checked by the scan's
    edge samples ``scan`` (world frame; None: not checked); ``part`` (N, 3): the scan's
    points on the part, whose heights by each piece cut its edges a second time (None: the
    splat's heights only). Why not, as a sentence, when the frame is not the camera's or
    shows too little of the outline."""
    if image.shape[:2] != (camera.height, camera.width):
        return (f"the frame is {image.shape[1]}×{image.shape[0]} px, the camera "
                f"{camera.width}×{camera.height}")
    rough = outline(heights)
    tops = _tops(heights, part)
    rough = replace(rough, points=np.column_stack([rough.points[:, :2], top_heights(
        heights, rough.points[:, :2], rough.normals)]))
    pieces, found, seen, left_out = frame_pieces(heights, frame_of(image), camera, rough,
                                                 tops, part is not None, part)
    if seen < 50:
        return f"{seen} of the outline's {len(rough.points)} points in the camera's view"
    covered = found / len(rough.points)
    inset = float("nan")
    if scan is not None and len(scan):
        pieces, inset = _anchored(pieces, scan)
        pieces += _from_scan(pieces, rough, scan, inset)
    pieces = [replace(q, view_deg=view_deg(heights, q, camera)) for q in pieces]
    if not pieces:
        return (f"no straight or round edge fitted to the {found} edge points the frame "
                f"shows of the outline's {len(rough.points)}"
                + (f" ({left_out} left out: the scan's top runs on across them, a shadow's, "
                   "a texture's or a slope's grey step)" if left_out else ""))
    known = [q.offset_mm for q in pieces if np.isfinite(q.offset_mm)]
    shift = float(np.median(known)) if known else 0.0
    return OutlineFit(_sampled(heights, pieces, tops), tuple(pieces), float(covered), inset,
                      _sampled(heights, [q.moved(-q.offset_mm if np.isfinite(q.offset_mm)
                                                 else -shift) for q in pieces], tops))


def _sampled(heights: HeightImage, pieces: list[Piece], tops) -> Outline:
    """The pieces sampled every ``SPACING_MM``, with the heights ``tops`` gives (points (K, 2),
    outward normals (K, 2) → (K,) mm), the surface's beyond from ``heights``, and each
    piece's 1σ across it and of its turn: its fit's with the floor of a piece the crossed
    scan's lines check, or not (:func:`insitu.locate.uncertainty.reference_floor`)."""
    pts, nrm = (np.concatenate(a) for a in zip(*(q.sample(SPACING_MM) for q in pieces)))
    below = edge_heights(heights, pts, nrm)[1]
    count = [len(q.sample(SPACING_MM)[0]) for q in pieces]
    floor = [floor_of(q) for q in pieces]
    sigma = np.repeat([np.hypot(f[0], q.sigma_mm) for f, q in zip(floor, pieces)], count)
    tilt = np.repeat([np.hypot(f[1], q.tilt_mm) for f, q in zip(floor, pieces)], count)
    return Outline(np.column_stack([pts, tops(pts, nrm)]), nrm, below, sigma, tilt)


def floor_of(piece: Piece) -> tuple[float, float]:
    """(1σ across, of the turn ± at its ends), mm, of ``piece`` beyond its fit's own
    (:func:`insitu.locate.uncertainty.reference_floor`)."""
    ends = (piece.source == "scan" and piece.length_mm >= LINE_ENDS_MIN[0]
            and piece.points >= LINE_ENDS_MIN[1])
    return reference_floor(piece.rms_mm, checked(piece), "scan" if ends else "frame")


def checked(piece: Piece) -> bool:
    """Whether the crossed scan's lines check ``piece``: its offset measured from at least
    ``MIN_CHECK`` samples, and its top seen less obliquely than ``GRAZING_DEG``."""
    return bool(piece.scan >= MIN_CHECK and np.isfinite(piece.offset_mm)
                and piece.view_deg < GRAZING_DEG)


def view_deg(heights: HeightImage, piece: Piece, camera: CameraModel) -> float:
    """How obliquely, degrees, ``camera`` sees the top ``DEEP_MM[1]`` inside ``piece`` (the
    median angle between the top's normal, from ``heights``' slope, and the ray to the
    camera)."""
    pts, nrm = piece.sample(SPACING_MM)
    inner = pts - DEEP_MM[1] * nrm
    (gx, gy), z = heights.slope, heights.z
    sx, sy, sz = sample([gx, gy, z], *heights.pixel(inner))
    normal = np.column_stack([-sx, -sy, np.ones(len(inner))])
    ray = camera.centre_world - np.column_stack([inner, sz])
    cos = np.einsum("ij,ij->i", normal, ray) / (np.linalg.norm(normal, axis=1)
                                                * np.linalg.norm(ray, axis=1))
    return float(np.degrees(np.arccos(np.clip(np.median(cos), -1.0, 1.0))))


def _tops(heights: HeightImage, part: np.ndarray | None):
    """The top's height at edge points (K, 2) with outward normals (K, 2), mm: the scan's
    points' (:func:`scan_heights`) where they give it, else the splat's
    (:func:`top_heights`)."""
    tree = None if part is None or not len(part) else cKDTree(part[:, :2])

    def tops(edge: np.ndarray, n: np.ndarray) -> np.ndarray:
        splat = top_heights(heights, edge, n)
        return splat if tree is None else scan_heights(tree, part[:, 2], edge, n, splat)
    return tops


def scan_heights(tree: cKDTree, z: np.ndarray, edge: np.ndarray, n: np.ndarray,
                 fallback: np.ndarray) -> np.ndarray:
    """(K,) mm: the top's height at each edge point ``edge`` (K, 2): a line through the
    heights ``z`` (N,) of the scan points (``tree`` of their x, y) nearest to places every
    0.15 mm of ``DEEP_MM`` inside along the outward normal ``n`` (K, 2), carried on to the
    edge; ``fallback`` (K,) where fewer than three such points lie within ``NEAREST_MM``."""
    depth = np.arange(DEEP_MM[0], DEEP_MM[1] + 1e-9, 0.15)
    q = edge[:, None, :] - depth[None, :, None] * n[:, None, :]
    dist, k = tree.query(q.reshape(-1, 2), distance_upper_bound=NEAREST_MM)
    ok = np.isfinite(dist).reshape(len(edge), -1)
    zz = np.where(ok, np.append(z, 0.0)[np.minimum(k, len(z))].reshape(ok.shape), 0.0)
    m = ok.sum(axis=1)
    mm = np.maximum(m, 1)
    d_mean = (ok * depth).sum(axis=1) / mm
    z_mean = zz.sum(axis=1) / mm
    dd = np.where(ok, depth - d_mean[:, None], 0.0)
    slope = (dd * (zz - z_mean[:, None])).sum(axis=1) / np.maximum((dd ** 2).sum(axis=1),
                                                                     1e-12)
    return np.where(m >= 3, z_mean - slope * d_mean, fallback)


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
            fitted(xy[keep], rough.normals[k][keep], scan.points[keep, 2], SCAN_SPACING_MM,
                    "scan")]


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
