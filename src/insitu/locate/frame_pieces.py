"""The straight and round edges a reference's room-light frame shows
(:mod:`insitu.locate.outline_fit`), found in two passes.

The splat's rough outline (:func:`insitu.locate.image_edges.outline`) is projected into the
frame and along each point's normal the steepest grey step within ``SEARCH_PX`` is its edge,
cut at the top's height. About a rough outline those steps scatter: a scan whose lines lie
1 mm apart gives a rough edge up to a millimetre off and turned toward the lines, and a
tenth of a side's steps are then the wall's foot or the top's texture. So the steps are
first fitted loosely (:data:`insitu.locate.pieces.LOOSE`): each line or circle is only where
to look again. Along it (its own points, normals and heights) the frame's steps are found
once more and fitted as the edge. A piece is kept where it runs along the rough outline and
where the scan's top ends at it (:func:`continued`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial import cKDTree

from insitu.geometry.camera import CameraModel
from insitu.locate.height_image import HeightImage
from insitu.locate.image_edges import (
    SPACING_MM,
    STEP_PX,
    WALL_PX,
    Frame,
    Outline,
    edge_heights,
    edge_points,
    visible,
    wall_px,
)
from insitu.locate.pieces import Piece, fitted

SEARCH_PX = 6.0
"""How far from the splat's rough edge (or a loose piece) the frame's is looked for (its
edges lie up to a few tenths of a mm off)."""
ROUGH_MM = 0.5
"""A frame's piece must run this close to the splat's rough outline (whose edges lie up to
0.3 mm out: the table beside a wall is in shadow)."""
BESIDE_MM = (0.3, 1.2)
"""A frame's piece is an edge only where the scan's top ends at it: of the scan's points on
the part this far beside it, those outward lie beyond the top (the table, left out of the
part's points) or a step below it (more than ``STEP_MM``). Where the top runs on across a
piece, its grey step is a texture's, a shadow's or a slope's (the independent renderer's arc:
two such pieces 1.5–1.9 mm off its edge, fitted to 0.04–0.08 mm rms); 0.3 mm is 3σ of a piece
the scan does not check (:data:`insitu.locate.uncertainty.SCAN_REFERENCE_MM`)."""
STEP_MM = 1.0
CONTINUED = 0.5
"""A piece is left out where the scan's points on the top beyond it number more than this
share of those inside it."""

Tops = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""The top's height (K,) mm at edge points (K, 2) with outward normals (K, 2)."""


def frame_pieces(heights: HeightImage, frame: Frame, camera: CameraModel, rough: Outline,
                 tops: Tops, recut: bool, part: np.ndarray | None = None
                 ) -> tuple[list[Piece], int, int, int]:
    """(the pieces fitted to the frame's edges that run along the ``rough`` outline, how many
    edge points were found about its points in view (not on a wall seen edge-on), of how many,
    how many pieces were left out). ``tops``: the top's heights at edge points, at which each
    edge point's ray is cut again (twice: its height where it was found) when ``recut``.
    ``part`` (N, 3): the scan's points on the part; a piece the top runs on beyond is left out
    (:func:`continued`)."""
    e, n, z, found, seen = _steps(heights, frame, camera, rough, tops if recut else None)
    if seen < 50:
        return [], 0, seen, 0
    pieces = []
    for loose in fitted(e, n, z, SPACING_MM, loose=True):
        pts, nrm = loose.sample(SPACING_MM)
        along = Outline(np.column_stack([pts, tops(pts, nrm)]), nrm,
                        edge_heights(heights, pts, nrm)[1])
        e2, n2, z2, _, _ = _steps(heights, frame, camera, along, tops if recut else None)
        pieces += [q for q in fitted(e2, n2, z2, SPACING_MM) if _near_rough(q, rough)]
    kept = pieces if part is None else where_the_top_ends(pieces, part)
    return kept, found, seen, len(pieces) - len(kept)


def _steps(heights: HeightImage, frame: Frame, camera: CameraModel, edges: Outline,
           tops: Tops | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """(edge points (F, 2), their normals (F, 2) and heights (F,), F, how many of ``edges``'
    points were looked at): the frame's steps within ``SEARCH_PX`` of ``edges``' points in
    view and not on a wall seen edge-on, each ray cut at the point's height and, with
    ``tops``, twice more at the top's height where it was found."""
    width = wall_px(edges, camera, 0.0, np.zeros(3))
    seen = visible(heights, edges, camera, 0.0, np.zeros(3)) & ~((width > 0) & (width < WALL_PX))
    p, n = edges.points[seen], edges.normals[seen]
    if not len(p):
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), 0, 0
    offs = np.arange(-SEARCH_PX, SEARCH_PX + 1e-9, STEP_PX)
    found, e, _ = edge_points(frame, camera, p, n, offs,
                              np.where(width[seen] > 0, width[seen] / 2, np.inf))
    e, n, z = e[found], n[found], p[found, 2]
    if tops is not None and len(e):
        o, dirs = camera.rays(camera.project(np.column_stack([e, z])))
        for _ in range(2):
            z = tops(e, n)
            e = o[:2] + dirs[:, :2] * ((z - o[2]) / dirs[:, 2])[:, None]
    return e, n, z, int(found.sum()), int(seen.sum())


def where_the_top_ends(pieces: list[Piece], part: np.ndarray) -> list[Piece]:
    """The frame's ``pieces`` at which the scan's top, its points on the part (N, 3), ends:
    :func:`continued` at most ``CONTINUED``."""
    return [q for q in pieces if continued(q, part) <= CONTINUED]


def continued(piece: Piece, part: np.ndarray) -> float:
    """How many of the scan's points on the part (N, 3) lie ``BESIDE_MM`` outward of
    ``piece`` less than ``STEP_MM`` below its height, over how many lie as far inside it
    (0: the top ends at it; about 1: it runs on across it)."""
    pts, nrm = piece.sample(SPACING_MM)
    tree = cKDTree(part[:, :2])
    mid, half = np.mean(BESIDE_MM), np.ptp(BESIDE_MM) / 2
    near = [np.unique(np.concatenate(tree.query_ball_point(pts + side * mid * nrm, half))
                      .astype(np.int64)) for side in (-1.0, 1.0)]
    inside, outside = near[0], near[1][part[near[1], 2] > piece.z_mm - STEP_MM]
    return len(outside) / max(len(inside), 1)


def _near_rough(piece: Piece, rough: Outline) -> bool:
    """Whether ``piece`` runs along the rough outline (within ``ROUGH_MM``, median): not the
    foot of a wall the camera sees, or a shadow's edge."""
    pts, _ = piece.sample(SPACING_MM)
    return bool(np.median(cKDTree(rough.points[:, :2]).query(pts)[0]) < ROUGH_MM)
