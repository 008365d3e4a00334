"""How well a located pose is known: the covariance of a fit's turn and shift from its edge
points, counting the errors that do not average out along an edge.

The edge steps (:mod:`insitu.locate.edge_align`, :mod:`insitu.locate.image_edges`) fit a turn
and a shift (and the scan's inset) by weighted least squares on distances across the part's
edges. Treating those distances as independent gives a σ that shrinks as 1/√N with the points
an edge gives — and misses what they share: a line-end that overshoots the same way all along
one edge, a room light that moves an edge's grey step by the same fraction of a pixel (a lit
wall, a shadow), a pixel grid an edge runs along. So:

* **Segments** (:data:`SEGMENT_MM` of an edge) are the units that vary independently: the
  covariance is the cluster-robust (sandwich) one over segments, as a block bootstrap over
  them would give (Liang & Zeger 1986; the small-sample factor G/(G − p)); never below the
  independent points' own.
* **Edges** (points chained :data:`LINK_MM` apart at most, facing within :data:`EDGE_DEG`,
  on one level within :data:`LEVEL_MM`) may each be off as a whole by a bias that no
  residual shows (an edge moved as a whole moves the fit with it): a random bias per edge of
  ``bias_mm``, and one growing linearly along it to ± ``bias_mm`` at its ends (an edge
  turned), are added (their covariance through the fit).
* A room-light frame's edge is read to a fraction of a pixel, and that fraction is pulled
  toward the pixel grid (the sensor's pixels integrate the step): along an edge that runs
  within a pixel of one row or column end to end the pull changes smoothly and turns the edge
  (:data:`LOCK_PX`), along one that crosses many rows it averages out; what remains is the
  light's (:data:`FRAME_TILT_PX`) — :func:`frame_tilt`.
* The σ that counts is at the part's rim: the largest 1σ displacement the turn and shift give
  any point of the part's outline (:func:`rim_sigma`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

SEGMENT_MM = 3.0
EDGE_DEG = 20.0
LEVEL_MM = 0.5
LINK_MM = 2.0
SCAN_BIAS_MM = 0.02
"""1σ of one edge's inset about the part's, along its lines (the scan's edge step), and of the
change along it end to end. Chosen on the simulated corpus' tuning half
(benchmarks/locate_corpus.py; binning 2, 17 poses): every pose within 2.2σ at its rim and
1.6σ in its turn (the independent points' σ: 4.5σ)."""
FRAME_BIAS_PX = 0.1
"""The same for one edge's grey step in the room-light frame, camera pixels (its change along
the edge: :func:`frame_tilt`). Chosen on the same half under four room lights (69 frames):
every pose within 2.3σ at its rim (the arc at 51° under a low lamp, 0.048 mm: a lit wall
beside its top) and 2.1σ in its turn (the independent points' σ: 27σ)."""
FRAME_TILT_PX = 0.03
LOCK_PX = 0.15
"""± at its ends, px, of a frame's edge turned by the light (a lamp's fall-off, a shadow) and
by the pull toward the pixel grid when it runs within a pixel of a row or column (over a span
of ``s`` rows or columns, ``LOCK_PX / s`` when s > 1). Chosen on the tuning half (72 frames,
CAD): the insert's side 0.3° off a pixel row turned 0.5 px end to end read bilinearly, 0.28
px through a cubic spline; sides that cross 10–60 rows, 0.03 px."""


CHECKED_MM = 0.008
"""1σ across a scan reference's piece its crossed scan's lines cross (at least
``outline_fit.MIN_CHECK`` of them, its offset from them measured, its top not seen at a
grazing angle), clearly lit, about the offset all its pieces share: fitted robustly and cut at the
scan's heights, the pieces so checked lay +0.012 mm (mean) from the CAD outline on the
simulated corpus' references (step block, arc, insert, four lights), each within 0.005–0.016
(1σ by light) of that mean. The shared part is the frame's grey step read as every later
frame's is read: it moves the reference's edges and a later part's alike and cancels in the
pose, whose own frame's per-edge bias (:data:`FRAME_BIAS_PX`) is counted there."""


@dataclass(frozen=True)
class FitTerms:
    """What a weighted least-squares edge fit ended on: ``J`` (K, p) its Jacobian (turn in
    rad, shift in mm, …), ``w`` (K,) weights, ``r`` (K,) residuals across the edges, mm;
    ``xy`` (K, 2) the points (a fixed frame, mm), ``normals`` (K, 2) their edges' outward
    normals, ``z`` (K,) their heights, mm; ``along`` (K,) how much of a bias along the
    point's own direction shows across its edge (1: biases act across the edge; the scan's
    ν); ``spread_mm`` the residuals' robust 1σ; ``tilt`` (K,) the change of the point's
    edge's bias end to end, ± in the bias' unit (None: the bias itself; a frame's:
    :func:`frame_tilt`); ``reference`` (K,) 1σ of the reference's outline at each point, mm
    (None: ``reference_mm`` of :func:`covariance` for all), ``reference_tilt`` (K,) of the
    change of its edge's error end to end, ± mm (None: as ``reference``)."""

    J: np.ndarray
    w: np.ndarray
    r: np.ndarray
    xy: np.ndarray
    normals: np.ndarray
    z: np.ndarray
    along: np.ndarray
    spread_mm: float
    tilt: np.ndarray | None = None
    reference: np.ndarray | None = None
    reference_tilt: np.ndarray | None = None


SCAN_REFERENCE_MM = {"checked": CHECKED_MM, "fitted": 0.1, "splat": 0.15}
CHECKED_TILT_MM = 0.01
"""The same for a checked piece's turn, ± at its ends: the pieces' errors changed by −0.005 …
+0.012 mm end to end under diffuse light and a lamp, by up to ±0.04 mm under the textured
low-contrast light (their points scatter 0.024–0.028 mm rms there)."""
CLEAR_RMS_MM = 0.02
"""A frame's edge points scatter this little (rms) about a clearly lit piece."""
LINE_ENDS_MM = (0.04, 0.03)
"""1σ across and of the turn (± at its ends) of a scan reference's piece fitted to its crossed
scan's line ends where its frame shows no edge (a wall lit as bright as the top, two tops
alike): on the simulated corpus' 12 references (three parts, four lights) its 10 such pieces
13–38 mm long lay +0.025 … +0.079 mm outward of the CAD outline, turned 0.045 … 0.143° (up to
±0.048 mm at their ends: the arc's end under the low lamp). The line ends scatter 0.06–0.08
mm rms about their piece, by the lines' own spacing across it, not by a weak grey step: the
frame's floor that grows with its points' scatter does not apply."""


def reference_floor(rms_mm: float, checked: bool, source: str = "frame"
                    ) -> tuple[float, float]:
    """(1σ, mm, of a scan reference's piece across it, of its turn ± at its ends) beyond
    what its own fit's scatter gives (:func:`insitu.locate.pieces.piece_sigma`): the grey
    step's bias, ``SCAN_REFERENCE_MM["checked"]`` (its turn :data:`CHECKED_TILT_MM`) when
    the crossed scan's lines check the piece, ``"fitted"`` otherwise, in proportion to its
    points' scatter ``rms_mm`` beyond :data:`CLEAR_RMS_MM` (a weak step, a textured or dim
    edge); a piece fitted to the scan's line ends (``source`` "scan"): :data:`LINE_ENDS_MM`."""
    if source == "scan":
        return LINE_ENDS_MM
    scale = max(1.0, rms_mm / CLEAR_RMS_MM)
    if checked:
        return SCAN_REFERENCE_MM["checked"] * scale, CHECKED_TILT_MM * scale
    return SCAN_REFERENCE_MM["fitted"] * scale, SCAN_REFERENCE_MM["fitted"] * scale


def edges_of(xy: np.ndarray, normals: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(K,) int: the edge each point lies on — points chained less than ``LINK_MM`` apart
    whose normals differ by less than ``EDGE_DEG`` and heights by less than ``LEVEL_MM``."""
    pairs = cKDTree(xy).query_pairs(LINK_MM, output_type="ndarray")
    if len(pairs):
        a, b = pairs.T
        same = ((np.einsum("ij,ij->i", normals[a], normals[b]) > np.cos(np.radians(EDGE_DEG)))
                & (np.abs(z[a] - z[b]) < LEVEL_MM))
        pairs = pairs[same]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])) if len(pairs)
                       else ([], ([], [])), shape=(len(xy), len(xy)))
    return connected_components(graph, directed=False)[1]


def frame_tilt(xy: np.ndarray, normals: np.ndarray, z: np.ndarray, uv: np.ndarray
               ) -> np.ndarray:
    """(K,) px: the change end to end (±) of each frame edge's bias (:data:`LOCK_PX`,
    :data:`FRAME_TILT_PX`) for points ``xy`` (K, 2), ``normals`` (K, 2), ``z`` (K,) mm on
    the edges of :func:`edges_of`, seen at the pixels ``uv`` (K, 2): the rows or columns an
    edge crosses are the fewer of its extent in u and in v."""
    edges = edges_of(xy, normals, z)
    out = np.zeros(len(xy))
    for e in np.unique(edges):
        sel = edges == e
        span = float(min(np.ptp(uv[sel, 0]), np.ptp(uv[sel, 1])))
        out[sel] = np.hypot(FRAME_TILT_PX, LOCK_PX / max(span, 1.0))
    return out


def along_edges(xy: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(K,) each point's position along its edge (``edges`` (K,) of :func:`edges_of`), mm
    from the edge's middle along its main direction, over the edge's half length (−1 … 1)."""
    out = np.zeros(len(xy))
    for e in np.unique(edges):
        sel = np.flatnonzero(edges == e)
        d = xy[sel] - xy[sel].mean(axis=0)
        axis = np.linalg.svd(d, full_matrices=False)[2][0] if len(sel) > 1 else np.zeros(2)
        s = d @ axis
        out[sel] = (s - (s.max() + s.min()) / 2) / max(np.ptp(s) / 2, 1e-9)
    return out


def segments_of(xy: np.ndarray, edges: np.ndarray, length_mm: float) -> np.ndarray:
    """(K,) int: pieces ``length_mm`` long along each edge (``edges`` (K,) of
    :func:`edges_of`), along the edge's main direction."""
    out = np.zeros(len(xy), np.int64)
    start = 0
    for e in np.unique(edges):
        sel = np.flatnonzero(edges == e)
        d = xy[sel] - xy[sel].mean(axis=0)
        axis = np.linalg.svd(d, full_matrices=False)[2][0] if len(sel) > 1 else np.zeros(2)
        piece = np.floor((d @ axis - (d @ axis).min()) / length_mm).astype(np.int64)
        out[sel] = start + piece
        start += int(piece.max()) + 1
    return out


def covariance(t: FitTerms, bias_mm: float, segment_mm: float = SEGMENT_MM,
               reference_mm: float = 0.0) -> np.ndarray:
    """(p, p) covariance of the fit's unknowns (:class:`FitTerms`' columns): the larger (by
    trace) of the independent points' (spread² · A⁻¹) and the cluster-robust one over segments, plus
    a random bias per edge of 1σ ``bias_mm`` and one that changes linearly along it, ± ``bias_mm``
    at its ends (an edge turned: its bias grows with the distance to the camera, the light falls off
    along it; ± ``t.tilt`` where given); ``reference_mm``: the same, across the edge, for the
    reference's own outline (a scan's: :data:`SCAN_REFERENCE_MM`)."""
    J, w, r = t.J, t.w, t.r
    p = J.shape[1]
    A = J.T @ (J * w[:, None])
    Ai = np.linalg.inv(A)
    iid = t.spread_mm ** 2 * Ai
    edge = edges_of(t.xy, t.normals, t.z)
    seg = segments_of(t.xy, edge, segment_mm)
    G = int(seg.max()) + 1 if len(seg) else 0
    score = np.zeros((G, p))
    np.add.at(score, seg, J * (w * r)[:, None])
    robust = Ai @ (score.T @ score) @ Ai * (G / max(G - p, 1))
    cov = robust if np.trace(robust) > np.trace(iid) else iid
    E = int(edge.max()) + 1 if len(edge) else 0
    pos = along_edges(t.xy, edge)[:, None]
    ones = np.ones(len(w))
    tilt = ones if t.tilt is None or bias_mm <= 0 else t.tilt / bias_mm
    own = reference_mm * ones if t.reference is None else t.reference
    own_tilt = ones if t.reference_tilt is None else t.reference_tilt / np.maximum(own, 1e-12)
    for scale, along, turned in ((bias_mm, t.along, tilt), (float(own.max(initial=0.0)),
                                                             own / max(own.max(initial=0.0),
                                                                       1e-12), own_tilt)):
        if scale > 0:
            lever = np.zeros((2 * E, p))
            wj = J * (w * along)[:, None]
            np.add.at(lever, edge, wj)
            np.add.at(lever, E + edge, wj * (pos * turned[:, None]))
            cov = cov + scale ** 2 * Ai @ (lever.T @ lever) @ Ai
    return cov


def rim_sigma(cov: np.ndarray, rim: np.ndarray) -> float:
    """The largest 1σ displacement, mm, at the points ``rim`` (M, 2) mm (relative to where
    the turn is about) of a turn and shift with covariance ``cov`` (3, 3): turn (rad), x, y
    (mm) first."""
    if not np.all(np.isfinite(cov[:3, :3])):
        return float("inf")
    worst = 0.0
    for q in rim:
        D = np.array([[-q[1], 1.0, 0.0], [q[0], 0.0, 1.0]])
        worst = max(worst, float(np.linalg.eigvalsh(D @ cov[:3, :3] @ D.T).max()))
    return float(np.sqrt(worst))


def rim_moved(rim: np.ndarray, T_a: np.ndarray, T_b: np.ndarray) -> float:
    """How far, mm, two poses (4, 4; part → world) put the points ``rim`` (M, 2), part frame,
    apart at most."""
    q = np.column_stack([rim, np.zeros(len(rim))])
    return float(np.linalg.norm((q @ T_a[:3, :3].T + T_a[:3, 3])[:, :2]
                                - (q @ T_b[:3, :3].T + T_b[:3, 3])[:, :2], axis=1).max())


@dataclass(frozen=True)
class OutlineHold:
    """How well a reference's own outline can hold a part located against it, every edge of
    it seen and the frame's edges error-free: ``cov`` (3, 3) of the turn (rad, about the
    top's centre) and shift (mm) from its edges' own errors alone, ``rim_mm`` its 1σ at the
    part's rim, ``x_mm``, ``y_mm`` (1σ along the part frame's axes) and ``turn_deg``; the
    ``weakest`` direction (2,) of the shift (unit, part frame)."""

    cov: np.ndarray
    rim_mm: float
    x_mm: float
    y_mm: float
    turn_deg: float
    weakest: np.ndarray


def outline_hold(xy: np.ndarray, normals: np.ndarray, z: np.ndarray, sigma_mm: np.ndarray,
                 tilt_mm: np.ndarray, rim: np.ndarray) -> OutlineHold:
    """:class:`OutlineHold` of an outline's points ``xy`` (K, 2) mm, outward ``normals``
    (K, 2), heights ``z`` (K,), each point's 1σ across its edge ``sigma_mm`` (K,) and of its
    edge's turn ± at its ends ``tilt_mm`` (K,), for a part whose rim is ``rim`` (M, 2): the
    least-squares fit's covariance with no scatter and no light's bias, only the outline's
    own per-edge errors (:func:`covariance`) — a lower bound on a located pose's σ."""
    centre = xy.mean(axis=0)
    lever = xy - centre
    J = np.column_stack([normals[:, 1] * lever[:, 0] - normals[:, 0] * lever[:, 1], normals])
    ones = np.ones(len(xy))
    t = FitTerms(J, ones / np.maximum(sigma_mm, 1e-6) ** 2, np.zeros(len(xy)), xy, normals,
                 z, ones, 0.0, reference=sigma_mm, reference_tilt=tilt_mm)
    cov = covariance(t, 0.0)
    shift = cov[1:, 1:]
    vals, vecs = np.linalg.eigh(shift)
    return OutlineHold(cov, rim_sigma(cov, rim - centre), float(np.sqrt(shift[0, 0])),
                       float(np.sqrt(shift[1, 1])), float(np.degrees(np.sqrt(cov[0, 0]))),
                       vecs[:, -1])
