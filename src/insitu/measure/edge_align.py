"""The last step of locating a part: x, y and the turn from the top's edges, as each scan line
measures them.

A scan line samples the surface densely along itself (a pixel apart) but the lines lie
0.5 mm apart: point-to-plane ICP gets no hold in x, y from flat tops, and an edge is only
known where a line crosses it. There it is known well: the last point of a top before the
surface drops (to the table, a lower step or a hole, or down a wall) lies within one sample
spacing inside the edge (and a line loses a little more where its light is cut by the edge).
Each such *edge sample* e with its outward line direction u gives the distance s, along u,
from e to the reference's edge (found on the reference's height image seen from above); the
fit turns and shifts the part until every s is the same b, fitted along (least squares, Huber
weights). Only the upper side of a drop is used: the lower side lies
in the shadow of the wall or hidden behind its top.
"""

from __future__ import annotations

import numpy as np

from insitu.measure.height_image import HeightImage, sample

DROP_MM = 0.5
"""A top ends where the next point along the line lies this much lower (or on a wall)."""
FLAT_MM = 0.15
"""...and the point before it on the top lies within this height of it."""
SEARCH_MM = 1.0
HUBER_MM = 0.05


def edge_samples(points: np.ndarray, lines: np.ndarray, wall: np.ndarray,
                 table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The scan's edge samples: (points (K, 3), outward unit directions along their lines
    (K, 2)) from ``points`` (N, 3) world
    frame, their ``lines`` (N,) index, and whether each lies on a wall or the table (N,)
    bool."""
    order = np.lexsort((_along(points, lines), lines))
    p, ln, w, tb = points[order], lines[order], wall[order], table[order]
    top = ~w & ~tb
    out_p, out_u = [], []
    for step in (1, -1):                       # forward along the line, then backward
        q, l2, w2, t2 = (p, ln, w, top) if step == 1 else (p[::-1], ln[::-1], w[::-1],
                                                            top[::-1])
        prev, cur, nxt = q[:-2], q[1:-1], q[2:]
        same = (l2[:-2] == l2[1:-1]) & (l2[1:-1] == l2[2:])
        flat = np.abs(cur[:, 2] - prev[:, 2]) < FLAT_MM
        drop = w2[2:] | (cur[:, 2] - nxt[:, 2] > DROP_MM)
        k = np.flatnonzero(same & t2[1:-1] & t2[:-2] & flat & drop)
        d = nxt[k, :2] - prev[k, :2]
        u = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        out_p.append(cur[k])
        out_u.append(u)
    return np.vstack(out_p), np.vstack(out_u)


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


def edge_distance(heights: HeightImage, e: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(K,) distance s, mm, along ``u`` (K, 2) from each edge sample ``e`` (K, 3) (part
    frame) to where the reference's height first falls below halfway between the sample's
    height and the reference's height ``SEARCH_MM`` beyond; NaN where it does not within
    ±``SEARCH_MM``."""
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
    return np.where(found, s[j - 1] + f * (s[j] - s[j - 1]), np.nan)


def align_edges(heights: HeightImage, e: np.ndarray, u: np.ndarray,
                iterations: int = 10) -> tuple[float, np.ndarray, float, int] | None:
    """The correction (angle_rad, (2,) shift mm) that moves the edge samples ``e`` (K, 3),
    part frame, with outward directions ``u`` (K, 2), so that each lies the same distance b
    inside the reference's edge (a corrected point is ``Rz(angle) @ p + shift``, x, y only),
    with that b, mm (half a sample spacing and whatever the scan loses at an edge), and the
    samples used. None when fewer than 20 samples find an edge or the edges do not hold the
    turn, both shifts and b (edges in one direction only)."""
    theta, t, b = 0.0, np.zeros(2), 0.0
    c = e[:, :2].mean(axis=0) if len(e) else np.zeros(2)
    used = 0
    for _ in range(iterations):
        R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        pe = np.column_stack([(e[:, :2] - c) @ R.T + c + t, e[:, 2]])
        ue = u @ R.T
        s = edge_distance(heights, pe, ue)
        ok = np.isfinite(s)
        used = int(ok.sum())
        if used < 20:
            return None
        r = s[ok] - b
        d = pe[ok, :2] - c - t
        J = np.column_stack([-ue[ok, 0] * d[:, 1] + ue[ok, 1] * d[:, 0], ue[ok],
                             -np.ones(used)])
        w = np.minimum(1.0, HUBER_MM / np.maximum(np.abs(r - np.median(r)), 1e-12))
        A = J.T @ (J * w[:, None])
        if np.linalg.cond(A) > 1e6:
            return None
        x = np.linalg.solve(A, J.T @ (w * r))
        theta, t, b = theta + x[0], t + x[1:3], b - x[3]
        if abs(x[0]) < 1e-7 and np.linalg.norm(x[1:]) < 1e-4:
            break
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    return float(theta), c - R @ c + t, float(b), used
