"""The last step of locating a part: x, y and the turn from the top's edges, as each scan line
measures them.

A scan line samples the surface densely along itself (a pixel apart) but the lines lie
0.5 mm apart: point-to-plane ICP gets no hold in x, y from flat tops, and an edge is only
known where a line crosses it. There it is known well: the last point of a top before the
surface drops (to the table, a lower step or a hole, or down a wall) lies a little inside the
edge. Each such *edge sample* e with its outward line direction u gives the distance s, along
u, from e to the reference's edge (found on the reference's height image seen from above).

Along each line the points are taken in the order of their pixels (the camera known): the
lower line beside an oblique edge lies shifted across the line, where the light plane meets
the floor, and in x, y begins before the top ends. How far inside its edge a top's last
point lies, along its line, is then about the same for every edge: the line's centre is
found pixel by pixel along the line until its light, clipped by the edge, falls below the
detector's threshold, a fraction of a pixel before the edge whatever angle the line crosses
it at. Across the edge that inset is the cosine ν between the line and the edge's normal
smaller: a line grazing an edge ends nearly on it. (One inset across the edges, fitted
before, put the grazing samples 0.02–0.03 mm too far in: a part held across by grazing lines
alone — an arc turned 15° to the lines, a step block turned ~180° — moved 0.06 mm.) So one
inset along the lines is fitted with the turn and the shift (least squares on the residuals
across the edges, Huber weights; a sample far beyond the others, its line cut short, weighs
nothing), then x, y with the turn kept. Only the upper side of a drop is used: the lower
side lies in the shadow of the wall or hidden behind its top.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.geometry.camera import CameraModel
from insitu.geometry.pose import rot_z
from insitu.locate.height_image import HeightImage, sample
from insitu.locate.uncertainty import SCAN_BIAS_MM, FitTerms, covariance

DROP_MM = 0.5
FLAT_MM = 0.15
REACH_MM = 0.6
STEEP = 2.0
LOOK = 8
"""Points along the line looked at for the drop."""
HOLD_PTS = 3
"""Steps along the line before a drop that must each stay within ``FLAT_MM`` (the top holds):
a line grazing an edge it runs along, flickering between the top and the floor, gives no
samples."""
ON_PIXELS = 0.9
"""Share of a scan's points that must project onto whole pixels (along their line) for the
camera to order them: it is the camera they were measured through."""
SEARCH_MM = 1.0
MIN_SAMPLES = 20
"""Fewer edge samples finding the reference's edge hold no fit."""
MIN_FOUND = 0.7
"""At the fitted pose this share of the edge samples must find the reference's edge."""
CORNER_MM = 0.3
STRAIGHT_MM = 0.05
"""How far (across the edge) the same line moved ``CORNER_MM`` along its edge may meet it: a
straight edge the same, the insert's 1.9 mm hole 0.025 mm away, a corner or a wall beside
the edge much further or not at all."""
MIN_COS = 0.1
"""Lines crossing an edge more obliquely than this (cosine to its normal) are not used. A line
grazing an edge still measures it across well (its distance along the line is searched for,
its residual is across): with 0.2 instead, an arc turned within 12° of the lines lost its
long sides' samples and its x was the ICP's on the curved top, 0.06 mm off (binning 1)."""
HUBER_MM = 0.03
CUT_MM = 0.15
"""A sample this much beyond the others' median inset: its line was cut short (no weight)."""
SHIFT_HUBER_MM = 0.05
"""The shift's Huber scale; no sample is cut there (a cut could hold a shift that drops
a whole edge)."""


@dataclass(frozen=True)
class EdgeSamples:
    """The scan's edge samples: ``points`` (K, 3) world frame, ``dirs`` (K, 2) outward unit
    directions along their lines."""

    points: np.ndarray
    dirs: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def edge_samples(points: np.ndarray, lines: np.ndarray, table: np.ndarray,
                 camera: CameraModel | None = None) -> EdgeSamples:
    """The edge samples of ``points`` (N, 3) world frame, their ``lines`` (N,) index and
    whether each is the table (N,) bool; ``camera``: the camera the points were measured
    through (their pixels are its projections), for the order along each line
    (:func:`_along`). A point ends a top when the ``HOLD_PTS`` steps before it on its line
    each stay within ``FLAT_MM``, the next point is lower by more than that or down a slope
    steeper than ``STEEP`` (a wall), the one after it lower too, and the line falls
    ``DROP_MM`` below it: at the next point, however far (past a shadow), or within
    ``REACH_MM`` (down a wall). A top cut short by something higher in the way is no edge:
    the reference shows no drop there, and :func:`edge_distance` finds none."""
    order = np.lexsort((_along(points, lines, camera), lines))
    p, ln, top = points[order], lines[order], ~table[order]
    out = []
    for q, l2, t2 in ((p, ln, top), (p[::-1], ln[::-1], top[::-1])):   # both ways along
        n = len(q)
        i = np.arange(1, max(n - 1, 1))
        ok = (l2[i - 1] == l2[i]) & (l2[i + 1] == l2[i]) & t2[i] & t2[i - 1]
        for k in range(HOLD_PTS):           # the top holds before the drop …
            j = np.maximum(i - k, 1)
            ok &= (l2[j - 1] == l2[i]) & (np.abs(q[j, 2] - q[j - 1, 2]) < FLAT_MM)
        j = np.minimum(i + 2, n - 1)          # … and the line stays down after it
        ok &= (l2[j] == l2[i]) & (q[i, 2] - q[j, 2] > FLAT_MM)
        dz = q[i, 2] - q[i + 1, 2]
        ok &= (dz > FLAT_MM) | (dz > np.maximum(STEEP * np.linalg.norm(q[i + 1, :2] - q[i, :2],
                                                                       axis=1), 0.03))
        fall = q[i, 2] - q[i + 1, 2]          # the next point, however far (past a shadow)
        for k in range(2, LOOK + 1):
            j = np.minimum(i + k, n - 1)
            near = (l2[j] == l2[i]) & (np.linalg.norm(q[j, :2] - q[i, :2], axis=1) <= REACH_MM)
            fall = np.maximum(fall, np.where(near, q[i, 2] - q[j, 2], 0.0))
        k = i[ok & (fall > DROP_MM)]
        d = q[k, :2] - q[k - HOLD_PTS, :2]        # along the top: the next point, on the
        #                                           floor, lies shifted across the line
        out.append((q[k], d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)))
    return EdgeSamples(*(np.vstack([o[j] for o in out]) for j in range(2)))


def _along(points: np.ndarray, lines: np.ndarray,
           camera: CameraModel | None = None) -> np.ndarray:
    """Each point's position along its line: the pixel coordinate (u or v, whichever the
    line runs along in the image) when the scan was measured through ``camera`` — the order
    the centres were found in, one per whole pixel; else along the line's main direction in
    x, y, mm. Beside an oblique edge the lower line lies shifted across the line (the light
    plane leans) and begins, in x, y, before the top ends: only the pixels' order keeps the
    two apart. A camera the points do not fall on whole pixels of (under ``ON_PIXELS`` of
    them: another rig's, or a cloud from elsewhere) gives no order."""
    out = np.zeros(len(points))
    order = np.argsort(lines, kind="stable")
    groups = np.split(order, np.flatnonzero(np.diff(lines[order])) + 1) if len(lines) else []
    if camera is not None and len(points):
        # ordered through the pinhole (distortion keeps the order along a line; a tenth of
        # the time), checked on whole pixels through the full model on a sample
        cam = camera.to_camera(points)
        uv = cam[:, :2] / cam[:, 2:] * np.diag(camera.K)[:2] + camera.K[:2, 2]
        axis = np.zeros(len(points), int)
        for g in groups:
            a = int(np.ptp(uv[g, 1]) > np.ptp(uv[g, 0]))
            axis[g], out[g] = a, uv[g, a]
        some = np.linspace(0, len(points) - 1, min(len(points), 2000)).astype(int)
        px = camera.project(points[some])[np.arange(len(some)), axis[some]]
        if np.mean(np.abs(px - np.round(px)) < 0.05) >= ON_PIXELS:
            return out
    for g in groups:
        d = points[g, :2] - points[g, :2].mean(axis=0)
        axis = np.linalg.svd(d[:: max(1, len(d) // 200)], full_matrices=False)[2][0] \
            if len(d) > 1 else np.array([0.0, 1.0])
        out[g] = d @ axis
    return out


def crossed(points: np.ndarray, lines: np.ndarray, min_deg: float = 20.0) -> bool:
    """Whether the scan lines (``lines`` (N,) index of ``points`` (N, 3)) run in two
    directions at least ``min_deg`` apart in x, y (a crossed pass)."""
    order = np.argsort(lines, kind="stable")
    angles = []
    for g in np.split(order, np.flatnonzero(np.diff(lines[order])) + 1):
        if len(g) >= 10:
            d = points[g, :2] - points[g, :2].mean(axis=0)
            v = np.linalg.svd(d[:: max(1, len(d) // 100)], full_matrices=False)[2][0]
            angles.append(np.degrees(np.arctan2(v[1], v[0])) % 180.0)
    if not angles:
        return False
    gap = (np.asarray(angles) - angles[0] + 90.0) % 180.0 - 90.0
    return bool(np.ptp(gap) >= min_deg)


def edge_distance(heights: HeightImage, e: np.ndarray,
                  u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance s (K,) mm, the edge's outward unit normal there (K, 2)): s along ``u``
    (K, 2) from each edge sample ``e`` (K, 3) (part frame) to where the reference's height
    falls below halfway between the sample's height and the reference's height ``SEARCH_MM``
    beyond, nearest the sample (negative: the sample lies beyond the edge); NaN where it does
    not within ±``SEARCH_MM``, or where the edge does not run on straight ``CORNER_MM`` either
    way along the normal's edge: the same line moved there crosses it further than
    ``STRAIGHT_MM`` (across the edge) away or not at all — a corner, or a lower edge beside a
    higher wall whose slope the normal took."""
    dist = _crossing(heights, e, u)
    n = _normal(heights, e[:, :2] + np.nan_to_num(dist)[:, None] * u)
    nu = np.maximum(np.einsum("ij,ij->i", n, u), MIN_COS)
    tangent = np.column_stack([-n[:, 1], n[:, 0]])
    for side in (-1.0, 1.0):
        moved = e.copy()
        moved[:, :2] += side * CORNER_MM * tangent
        off = np.abs(_crossing(heights, moved, u) - dist) * nu
        dist = np.where(off <= STRAIGHT_MM, dist, np.nan)
    return dist, n


def _crossing(heights: HeightImage, e: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The distance s (K,) of :func:`edge_distance`, NaN where the height does not fall."""
    s = np.arange(-SEARCH_MM, SEARCH_MM + 1e-9, 0.02)
    xy = e[:, None, :2] + s[None, :, None] * u[:, None, :]
    cols, rows = heights.pixel(xy)
    h = sample([heights.z], cols.ravel(), rows.ravel())[0].reshape(xy.shape[:2])
    level = (e[:, 2] + h[:, -1]) / 2
    below = h < level[:, None]
    # the crossing nearest the sample: on from it when it lies on the top, back from it
    # when it lies already beyond the edge (a line's end blurred a little past it)
    start = int(np.argmin(np.abs(s)))
    cross = below[:, 1:] & ~below[:, :-1]          # between j − 1 and j, j = 1 … len(s) − 1
    jj = np.arange(1, len(s))
    after, before = cross & (jj > start), cross & (jj <= start)
    j = np.where(below[:, start],
                 np.where(before.any(1), len(s) - 1 - np.argmax(before[:, ::-1], axis=1), 0),
                 np.where(after.any(1), np.argmax(after, axis=1) + 1, 0))
    found = (j > 0) & (h[:, -1] < e[:, 2] - DROP_MM / 2)
    j = np.maximum(j, 1)
    h0, h1 = h[np.arange(len(e)), j - 1], h[np.arange(len(e)), j]
    f = np.clip((h0 - level) / np.where(h0 - h1 != 0, h0 - h1, 1.0), 0.0, 1.0)
    return np.where(found, s[j - 1] + f * (s[j] - s[j - 1]), np.nan)


def _normal(heights: HeightImage, xy: np.ndarray) -> np.ndarray:
    """The outward unit normals (K, 2) of the reference's edges at ``xy`` (K, 2): down its
    blurred slope (:attr:`HeightImage.slope`)."""
    g = -np.column_stack(sample(heights.slope, *heights.pixel(xy)))
    return g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)


@dataclass(frozen=True)
class EdgeFit:
    """A corrected point is ``Rz(angle_rad) @ p + shift_mm`` (x, y only); ``b_mm``: how far
    inside its edge a top's last point lies, along its line (on average: what the line's
    end loses); ``samples`` used; ``cov`` (3, 3): the covariance of the turn (rad, about
    ``centre_mm`` (2,), part frame) and the shift (mm) (:func:`insitu.locate.uncertainty.
    covariance`: segments of an edge vary together, each edge may be off by ``bias_mm``
    along its lines); None when a direction was left free; ``sigma_mm``, ``sigma_deg``: 1σ
    of the shift (its worst direction; across the free direction when one was) and of the
    turn — large when the edges the lines cross do not pin the part down."""

    angle_rad: float
    shift_mm: np.ndarray
    b_mm: float
    samples: int
    sigma_mm: float
    sigma_deg: float
    cov: np.ndarray | None = None
    centre_mm: np.ndarray | None = None
    terms: FitTerms | None = None


def align_edges(heights: HeightImage, e: np.ndarray, u: np.ndarray, iterations: int = 20,
                free: np.ndarray | None = None, bias_mm: float = SCAN_BIAS_MM,
                reference_mm: float = 0.0) -> EdgeFit | None:
    """The correction that moves the edge samples ``e`` (K, 3), part frame, with outward
    directions ``u`` (K, 2), onto the reference's edges, each inside by one inset b along
    its line (b·ν across the edge): first the turn, the shift and b (Huber weights; a
    sample far beyond the others, its line cut short, weighs nothing), then the shift and b
    with the turn kept (wider Huber weights, the cut samples kept out). None when fewer than
    20 samples, or less than ``MIN_FOUND`` of them, lie by an edge (the scan's edges are not
    the reference's there), when it moves a sample further than ``SEARCH_MM`` (beyond where
    the samples look for their edges: a slide along edges that do not hold it), or the
    edges cannot hold the turn and the shift. ``free``: a unit
    direction (2,), part frame, the shift is not fitted along (the one the edges hold least,
    :func:`unheld`): the turn and the shift across it only; ``sigma_mm`` is then the
    latter's. ``bias_mm``: 1σ of an edge's own inset about the part's (step heights, the
    light on a wall), ``reference_mm`` of the reference's edges, for the covariance."""
    if len(e) < MIN_SAMPLES:
        return None
    across = None if free is None else np.array([-free[1], free[0]])
    c = e[:, :2].mean(axis=0)
    first = _fit(heights, e, u, c, (0.0, np.zeros(2), 0.0), across, True, iterations)
    if first is None:
        return None
    (theta, t, b), _, A, r, cut = first
    second = _fit(heights, e, u, c, (theta, t, b), across, False, iterations, cut)
    if second is None:
        return None
    (theta, t, b), found, A, r, _ = second
    if (np.linalg.norm(_moved(e, u, c, theta, t)[0][:, :2] - e[:, :2], axis=1).max() > SEARCH_MM
            or near_edges(heights, e, u, c, theta, t) < MIN_FOUND * len(e)):
        return None                  # moved beyond where its samples look for their edges
    terms = _terms(heights, e, u, c, theta, t, b, across, cut)
    if terms is None:
        return None
    cov = covariance(terms, bias_mm, reference_mm=reference_mm)
    k = 2 if across is None else 1
    R = rot_z(theta)[:2, :2]
    return EdgeFit(float(theta), c - R @ c + t, b, found,
                   float(np.sqrt(np.linalg.eigvalsh(cov[1:k + 1, 1:k + 1]).max())),
                   float(np.degrees(np.sqrt(cov[0, 0]))),
                   cov[:3, :3] if across is None else None, c + t, terms)


def _terms(heights: HeightImage, e: np.ndarray, u: np.ndarray, c: np.ndarray, theta: float,
           t: np.ndarray, b: float, across: np.ndarray | None, cut: np.ndarray
           ) -> FitTerms | None:
    """The fit's :class:`~insitu.locate.uncertainty.FitTerms` at its end (turn, shift — along
    ``across`` only when given — and inset; the weights of its last stage)."""
    s, n, nu, d, ok = _residuals(heights, e, u, c, theta, t)
    r = (s - b) * nu
    w = _weights(r, SHIFT_HUBER_MM, np.inf) * ~np.isin(np.flatnonzero(ok), cut)
    J = np.column_stack([-n[:, 0] * d[:, 1] + n[:, 1] * d[:, 0],
                         n if across is None else (n @ across)[:, None], -nu])
    scale = np.sqrt(np.maximum(np.diag(J.T @ (J * w[:, None])), 1e-30))
    if (w > 0).sum() < MIN_SAMPLES or np.linalg.cond(
            J.T @ (J * w[:, None]) / np.outer(scale, scale)) > 1e4:
        return None
    return FitTerms(J, w, r, d + c + t, n, e[ok, 2], nu, _spread(r))


def _fit(heights: HeightImage, e: np.ndarray, u: np.ndarray, c: np.ndarray, start: tuple,
         across: np.ndarray | None, turn: bool, iterations: int, cut: np.ndarray | None = None):
    """Gauss–Newton on the residuals (s − b)·ν across the edges from ``start`` (theta, t,
    b): the turn (when ``turn``), the shift (only along ``across`` when given) and b.
    ``cut``: sample indices kept out; None: Huber weights that cut from the second step on
    (stage one), else the wider ones that do not.
    ((theta, t, b), samples found, normal matrix, residuals, the samples cut), or None."""
    theta, t, b = start
    k = 2 if across is None else 1
    for it in range(iterations):
        s, n, nu, d, ok = _residuals(heights, e, u, c, theta, t)
        if ok.sum() < MIN_SAMPLES:
            return None
        r = (s - b) * nu
        if cut is None:                   # none cut before the first step: the start is rough
            w = _weights(r, cut_mm=CUT_MM if it else np.inf)
        else:
            w = _weights(r, SHIFT_HUBER_MM, np.inf) * ~np.isin(np.flatnonzero(ok), cut)
        cols = [n if across is None else (n @ across)[:, None], -nu[:, None]]
        if turn:
            cols.insert(0, (-n[:, 0] * d[:, 1] + n[:, 1] * d[:, 0])[:, None])
        x, A = _solve(np.column_stack(cols), w, r)
        if x is None:
            return None
        dtheta, x = (x[0], x[1:]) if turn else (0.0, x)
        theta, t, b = theta + dtheta, t + (x[:k] if across is None else x[0] * across), b - x[k]
        if abs(dtheta) < 1e-7 and np.linalg.norm(x) < 1e-4:
            break
    return (theta, t, b), int(ok.sum()), A, r, (np.flatnonzero(ok)[w == 0] if cut is None
                                                  else cut)


def _moved(e: np.ndarray, u: np.ndarray, c: np.ndarray, theta: float, t: np.ndarray):
    """The samples ``e`` (K, 3) and directions ``u`` (K, 2) turned by theta about ``c``, then
    shifted by t."""
    R = rot_z(theta)[:2, :2]
    return np.column_stack([(e[:, :2] - c) @ R.T + c + t, e[:, 2]]), u @ R.T


def _residuals(heights: HeightImage, e: np.ndarray, u: np.ndarray, c: np.ndarray,
               theta: float, t: np.ndarray):
    """At the correction (theta about ``c``, then t): the samples' distances s to the
    reference's edge, its normals n, their cosines nu to the line, the lever arms d (only
    where the edge is found and crossed steeply enough), and that mask (K,)."""
    pe, ue = _moved(e, u, c, theta, t)
    s, n = edge_distance(heights, pe, ue)
    nu = np.einsum("ij,ij->i", n, ue)
    ok = np.isfinite(s) & (nu > MIN_COS)
    return s[ok], n[ok], nu[ok], pe[ok, :2] - c - t, ok


def near_edges(heights: HeightImage, e: np.ndarray, u: np.ndarray, c: np.ndarray,
                theta: float, t: np.ndarray) -> int:
    """How many samples lie by one of the reference's edges at the correction: found along
    their line or across it (a line that runs off an edge at a grazing angle ends far from
    it along the line, but beside it)."""
    pe, ue = _moved(e, u, c, theta, t)
    across = np.column_stack([-ue[:, 1], ue[:, 0]])
    near = np.zeros(len(e), bool)
    for d in (ue, across, -across):
        near |= np.isfinite(edge_distance(heights, pe, d)[0])
    return int(near.sum())


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
