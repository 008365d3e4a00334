"""The last step of locating a part: x, y and the turn from the top's edges, as each scan line
measures them.

A scan line samples the surface densely along itself (a pixel apart) but the lines lie
0.5 mm apart: point-to-plane ICP gets no hold in x, y from flat tops, and an edge is only
known where a line crosses it. There it is known well: the last point of a top before the
surface drops (to the table, a lower step or a hole, or down a wall) lies a little inside the
edge. Each such *edge sample* e with its outward line direction u gives the distance s, along
u, from e to the reference's edge (found on the reference's height image seen from above).

How far inside depends on how the line ends in the camera's image, which the sample's pixel
tells when the camera is known: the line's next detected pixel after the top's last one
lies ``gap`` pixels on (1: the lower line begins in the very next column, and the edge lies
at the last top pixel; 2: about half-way; 3 or more: dark columns, a shadow or the wall
between, and the top ends where its light falls below half, about a pixel on). So the
inset is the sample's step along its line (mm per pixel) times a factor per gap class, each
fitted with the turn and shift; a sample far beyond the others (a line cut short where the
lower line takes the same pixel columns) weighs nothing. The class factors lean on the
shift (the classes follow the edges' directions), so x, y are then fitted with the turn
kept and one inset for all (least squares, Huber weights, the cut samples kept out).
Only the upper side of a drop is used: the lower side lies
in the shadow of the wall or hidden behind its top.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.geometry.camera import CameraModel
from insitu.measure.flat_icp import rot_z
from insitu.measure.height_image import HeightImage, sample

DROP_MM = 0.5
FLAT_MM = 0.15
REACH_MM = 0.6
STEEP = 2.0
LOOK = 8
"""Points along the line looked at for the drop."""
SEARCH_MM = 1.0
MIN_SAMPLES = 20
"""Fewer edge samples finding the reference's edge hold no fit."""
MIN_FOUND = 0.7
"""At the fitted pose this share of the edge samples must find the reference's edge."""
CORNER_MM = 0.3
MIN_COS = 0.2
"""Lines crossing an edge more obliquely than this (cosine to its normal) are not used."""
HUBER_MM = 0.03
CUT_MM = 0.15
"""A sample this much beyond the others' median inset: its line was cut short (no weight)."""
SHIFT_HUBER_MM = 0.05
"""The shift's Huber scale; no sample is cut there (a cut could hold a shift that drops
a whole edge)."""
GAP_CLASSES = 3
"""Gap classes 1, 2 and ≥ 3 pixels (and one for samples without a camera)."""


@dataclass(frozen=True)
class EdgeSamples:
    """The scan's edge samples: ``points`` (K, 3) world frame, ``dirs`` (K, 2) outward unit
    directions along their lines, ``step_mm`` (K,) the spacing of their line's samples just
    inside (mm per pixel), ``gap_px`` (K,) how many pixels on the line's next detected point
    lies in the camera's image (NaN: no camera given)."""

    points: np.ndarray
    dirs: np.ndarray
    step_mm: np.ndarray
    gap_px: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def edge_samples(points: np.ndarray, lines: np.ndarray, table: np.ndarray,
                 camera: CameraModel | None = None) -> EdgeSamples:
    """The edge samples of ``points`` (N, 3) world frame, their ``lines`` (N,) index and
    whether each is the table (N,) bool; ``camera``: the camera the points were measured
    through (their pixels are its projections), for the gap. A point ends a top when the
    point before it on its line lies within ``FLAT_MM`` of its height, the next one lower by
    more than that or down a slope steeper than ``STEEP`` (a wall), and the line falls
    ``DROP_MM`` below it: at the next point, however far (past a shadow), or within
    ``REACH_MM`` (down a wall). A top cut short by something higher in the way is no edge:
    the reference shows no drop there, and :func:`edge_distance` finds none."""
    order = np.lexsort((_along(points, lines), lines))
    p, ln, top = points[order], lines[order], ~table[order]
    out = []
    for q, l2, t2 in ((p, ln, top), (p[::-1], ln[::-1], top[::-1])):   # both ways along
        n = len(q)
        i = np.arange(1, max(n - 1, 1))
        ok = (l2[i - 1] == l2[i]) & (l2[i + 1] == l2[i]) & t2[i] & t2[i - 1]
        ok &= np.abs(q[i, 2] - q[i - 1, 2]) < FLAT_MM
        dz = q[i, 2] - q[i + 1, 2]
        ok &= (dz > FLAT_MM) | (dz > np.maximum(STEEP * np.linalg.norm(q[i + 1, :2] - q[i, :2],
                                                                       axis=1), 0.03))
        fall = q[i, 2] - q[i + 1, 2]          # the next point, however far (past a shadow)
        for k in range(2, LOOK + 1):
            j = np.minimum(i + k, n - 1)
            near = (l2[j] == l2[i]) & (np.linalg.norm(q[j, :2] - q[i, :2], axis=1) <= REACH_MM)
            fall = np.maximum(fall, np.where(near, q[i, 2] - q[j, 2], 0.0))
        k = i[ok & (fall > DROP_MM)]
        d = q[k + 1, :2] - q[k - 1, :2]
        out.append((q[k], d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12),
                    q[k - 1], q[k + 1]))
    e, u, before, after = (np.vstack([o[j] for o in out]) for j in range(4))
    step = np.linalg.norm(e[:, :2] - before[:, :2], axis=1)
    gap = np.full(len(e), np.nan)
    if camera is not None and len(e):
        pe, pb, pa = (camera.project(x) for x in (e, before, after))
        d = pe - pb                         # the pixel axis the line is sampled along
        ax = np.argmax(np.abs(d), axis=1)
        r = np.arange(len(e))
        gap = (pa[r, ax] - pe[r, ax]) * np.sign(d[r, ax])
        step = step / np.maximum(np.abs(d[r, ax]), 1e-9)      # mm per pixel
    return EdgeSamples(e, u, step, gap)


def _along(points: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Each point's position along its line's main direction, mm."""
    out = np.zeros(len(points))
    for i in np.unique(lines):
        sel = lines == i
        xy = points[sel, :2]
        d = xy - xy.mean(axis=0)
        axis = np.linalg.svd(d[:: max(1, len(d) // 200)], full_matrices=False)[2][0] \
            if len(d) > 1 else np.array([0.0, 1.0])
        out[sel] = d @ axis
    return out


def edge_distance(heights: HeightImage, e: np.ndarray,
                  u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance s (K,) mm, the edge's outward unit normal there (K, 2)): s along ``u``
    (K, 2) from each edge sample ``e`` (K, 3) (part frame) to where the reference's height
    first falls below halfway between the sample's height and the reference's height
    ``SEARCH_MM`` beyond; NaN where it does not within ±``SEARCH_MM``, or where the edge
    turns within ``CORNER_MM`` (a corner holds no direction)."""
    s = np.arange(-SEARCH_MM, SEARCH_MM + 1e-9, 0.02)
    xy = e[:, None, :2] + s[None, :, None] * u[:, None, :]
    cols = (xy[..., 0] - heights.x0_mm) / heights.px_mm
    rows = (xy[..., 1] - heights.y0_mm) / heights.px_mm
    h = sample([heights.z], cols.ravel(), rows.ravel())[0].reshape(xy.shape[:2])
    level = (e[:, 2] + h[:, -1]) / 2
    below = h < level[:, None]
    # the first crossing at or after the sample's own height
    start = np.argmin(np.abs(s))
    below[:, :start] = False
    j = np.argmax(below, axis=1)
    found = below[np.arange(len(e)), j] & (j > 0) & (h[:, -1] < e[:, 2] - DROP_MM / 2)
    j = np.maximum(j, 1)
    h0, h1 = h[np.arange(len(e)), j - 1], h[np.arange(len(e)), j]
    f = np.clip((h0 - level) / np.where(h0 - h1 != 0, h0 - h1, 1.0), 0.0, 1.0)
    dist = np.where(found, s[j - 1] + f * (s[j] - s[j - 1]), np.nan)
    at = e[:, :2] + np.nan_to_num(dist)[:, None] * u
    d = 2 * heights.px_mm
    c = (at[:, 0] - heights.x0_mm) / heights.px_mm
    r = (at[:, 1] - heights.y0_mm) / heights.px_mm
    hx0, hx1, hy0, hy1 = sample([heights.z], np.concatenate([c - 2, c + 2, c, c]),
                                np.concatenate([r, r, r - 2, r + 2]))[0].reshape(4, -1)
    g = np.column_stack([hx1 - hx0, hy1 - hy0]) / (2 * d)
    n = -g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
    # a straight edge: the normal the same 0.3 mm along it either way (not a corner)
    for side in (-1.0, 1.0):
        at2 = at + side * CORNER_MM * np.column_stack([-n[:, 1], n[:, 0]])
        c = (at2[:, 0] - heights.x0_mm) / heights.px_mm
        r = (at2[:, 1] - heights.y0_mm) / heights.px_mm
        hx0, hx1, hy0, hy1 = sample([heights.z], np.concatenate([c - 2, c + 2, c, c]),
                                    np.concatenate([r, r, r - 2, r + 2]))[0].reshape(4, -1)
        g2 = -np.column_stack([hx1 - hx0, hy1 - hy0])
        cos = np.einsum("ij,ij->i", g2, n) / np.maximum(np.linalg.norm(g2, axis=1), 1e-12)
        dist = np.where(cos > np.cos(np.radians(20)), dist, np.nan)
    return dist, n


@dataclass(frozen=True)
class EdgeFit:
    """A corrected point is ``Rz(angle_rad) @ p + shift_mm`` (x, y only); ``b_mm``: how far
    inside its edge a top's last point lies along its line (on average: what sampling and
    the line's end lose); ``samples`` used; ``sigma_mm``, ``sigma_deg``: 1σ of the shift
    (its worst direction) and of the turn, from the residuals' spread — large when the
    edges the lines cross do not pin the part down (edges along the lines)."""

    angle_rad: float
    shift_mm: np.ndarray
    b_mm: float
    samples: int
    sigma_mm: float
    sigma_deg: float


def align_edges(heights: HeightImage, e: np.ndarray, u: np.ndarray,
                step_mm: np.ndarray | None = None, gap_px: np.ndarray | None = None,
                iterations: int = 20, free: np.ndarray | None = None) -> EdgeFit | None:
    """The correction that moves the edge samples ``e`` (K, 3), part frame, with outward
    directions ``u`` (K, 2), onto the reference's edges: first the turn, with each sample
    inside its edge by ``step_mm`` (K,) (1 when None) times a factor of its ``gap_px``
    class (:class:`EdgeSamples`; one class when None or NaN), then the shift with the turn
    kept and one inset b for all. None when fewer than 20 samples, or less than
    ``MIN_FOUND`` of them, find an edge (the scan's edges are not the reference's there), or
    the edges cannot hold the turn, the shift and the insets. ``free``: a unit direction (2,),
    part frame, the shift is not fitted along (edges that all face one way, :func:`unheld`):
    the turn and the shift across it only; ``sigma_mm`` is then the latter's."""
    if len(e) < MIN_SAMPLES:
        return None
    across = None if free is None else np.array([-free[1], free[0]])
    shift_cols = (lambda n: n) if across is None else (lambda n: (n @ across)[:, None])
    shift_of = (lambda x: x) if across is None else (lambda x: x[0] * across)
    k = 2 if across is None else 1              # the shift's unknowns
    step = np.ones(len(e)) if step_mm is None else np.asarray(step_mm, float)
    gap = np.full(len(e), np.nan) if gap_px is None else np.asarray(gap_px, float)
    cls = np.where(np.isfinite(gap), np.clip(np.round(np.nan_to_num(gap)), 1, GAP_CLASSES) - 1,
                   GAP_CLASSES).astype(int)
    c = e[:, :2].mean(axis=0)
    theta, t, beta = 0.0, np.zeros(2), np.zeros(GAP_CLASSES + 1)
    for _ in range(iterations):                   # the turn, an inset per gap class
        s, n, nu, d, ok = _residuals(heights, e, u, c, theta, t)
        if ok.sum() < MIN_SAMPLES:
            return None
        r = (s - step[ok] * beta[cls[ok]]) * nu
        w = _weights(r)
        present = np.flatnonzero(np.bincount(cls[ok], weights=w, minlength=len(beta)) >= 10)
        B = -(nu * step[ok])[:, None] * (cls[ok][:, None] == present[None, :])
        J = np.column_stack([-n[:, 0] * d[:, 1] + n[:, 1] * d[:, 0], shift_cols(n), B])
        x, A = _solve(J, w, r)
        if x is None:
            return None
        theta, t = theta + x[0], t + shift_of(x[1:1 + k])
        beta[present] -= x[1 + k:]
        cut = np.flatnonzero(ok)[w == 0]
        if abs(x[0]) < 1e-7 and np.linalg.norm(x[1:]) < 1e-4:
            break
    sigma_deg = float(np.degrees(_spread(r) * np.sqrt(np.linalg.inv(A)[0, 0])))
    b = float(np.median(s))
    for _ in range(iterations):                   # the shift with the turn kept, one inset
        s, n, nu, d, ok = _residuals(heights, e, u, c, theta, t)
        if ok.sum() < MIN_SAMPLES:
            return None
        r = (s - b) * nu
        w = _weights(r, SHIFT_HUBER_MM, np.inf) * ~np.isin(np.flatnonzero(ok), cut)
        x, A = _solve(np.column_stack([shift_cols(n), -nu]), w, r)
        if x is None:
            return None
        t, b = t + shift_of(x[:k]), b - x[k]
        if np.linalg.norm(x) < 1e-4:
            break
    if ok.sum() < MIN_FOUND * len(e):
        return None
    cov = _spread(r) ** 2 * np.linalg.inv(A)
    R = rot_z(theta)[:2, :2]
    return EdgeFit(float(theta), c - R @ c + t, b, int(ok.sum()),
                   float(np.sqrt(np.linalg.eigvalsh(cov[:k, :k]).max())), sigma_deg)


def _residuals(heights: HeightImage, e: np.ndarray, u: np.ndarray, c: np.ndarray,
               theta: float, t: np.ndarray):
    """At the correction (theta about ``c``, then t): the samples' distances s to the
    reference's edge, its normals n, their cosines nu to the line, the lever arms d (only
    where the edge is found and crossed steeply enough), and that mask (K,)."""
    R = rot_z(theta)[:2, :2]
    pe = np.column_stack([(e[:, :2] - c) @ R.T + c + t, e[:, 2]])
    ue = u @ R.T
    s, n = edge_distance(heights, pe, ue)
    nu = np.einsum("ij,ij->i", n, ue)
    ok = np.isfinite(s) & (nu > MIN_COS)
    return s[ok], n[ok], nu[ok], pe[ok, :2] - c - t, ok


def _weights(r: np.ndarray, huber_mm: float = HUBER_MM, cut_mm: float = CUT_MM) -> np.ndarray:
    """Huber weights about the median; none for a line cut short (``cut_mm`` beyond)."""
    dev = r - np.median(r)
    return np.where(dev > cut_mm, 0.0, np.minimum(1.0, huber_mm / np.maximum(np.abs(dev),
                                                                           1e-12)))


def _solve(J: np.ndarray, w: np.ndarray, r: np.ndarray):
    """(step, normal matrix) of weighted least squares; (None, None) when the columns
    (scaled to unit norm) are nearly dependent: the edges do not hold the unknowns."""
    A = J.T @ (J * w[:, None])
    scale = np.sqrt(np.maximum(np.diag(A), 1e-30))
    if np.linalg.cond(A / np.outer(scale, scale)) > 1e4:
        return None, None
    return np.linalg.solve(A, J.T @ (w * r)), A


def _spread(r: np.ndarray) -> float:
    """Robust 1σ of residuals r (MAD)."""
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


HOLD = 0.02
"""Below this share of the edges' normals (squared) along a direction, nothing holds it."""


def unheld(heights: HeightImage, e: np.ndarray, u: np.ndarray
           ) -> tuple[int, np.ndarray | None]:
    """Why :func:`align_edges` may find no fit at this pose: the edge samples ``e`` (K, 3),
    part frame, directions ``u`` (K, 2), that find the reference's edge, and the unit
    direction (2,) part frame along which their edges' normals give no hold (the least
    eigenvector of Σ n nᵀ / K, its eigenvalue below :data:`HOLD`; None: both held)."""
    s, n = edge_distance(heights, e, u)
    ok = np.isfinite(s) & (np.einsum("ij,ij->i", n, u) > MIN_COS)
    if not ok.any():
        return 0, None
    w, v = np.linalg.eigh(n[ok].T @ n[ok] / ok.sum())
    return int(ok.sum()), (v[:, 0] if w[0] < HOLD else None)


def unheld_reason(heights: HeightImage, e: np.ndarray, u: np.ndarray, total: int,
                  angle_rad: float) -> tuple[str, np.ndarray | None]:
    """Why the edges give no fit at a pose, and the direction (2,) part frame they leave
    free (None: none): too few of the scan's ``total`` edge samples (``e``, ``u`` in the
    part's frame) find the reference's edges, or those found all face one way (the free
    direction named in the world frame; ``angle_rad``: the world → part turn)."""
    found, free = unheld(heights, e, u)
    if free is None:
        enough = found >= MIN_SAMPLES and found >= MIN_FOUND * total
        return (f"{found} of the scan's {total} edge samples find the reference's edges"
                + (", but they settle into no one fit" if enough
                   else f" (at least {MIN_SAMPLES} and {MIN_FOUND:.0%} needed)")), None
    name, faces = direction_name(rot_z(-angle_rad)[:2, :2] @ free)   # part frame → world
    return (f"the {found} edges the scan lines cross all face {faces}: nothing holds the "
            f"part along {name}; turn the part or the scan so that lines cross edges that "
            f"face {name if name[0] == '(' else '±' + name}"), free


def direction_name(d: np.ndarray) -> tuple[str, str]:
    """A world direction (2,) named ("x", "y" or its components) and the edges across it
    ("±y", "±x", …)."""
    near = np.cos(np.radians(20))
    return (("x", "±y") if abs(d[0]) > near else ("y", "±x") if abs(d[1]) > near
            else (f"({d[0]:+.2f}, {d[1]:+.2f})", f"({-d[1]:+.2f}, {d[0]:+.2f})"))
