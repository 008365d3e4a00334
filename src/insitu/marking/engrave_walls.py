"""The walls' bias zones around a pocket's floor, and the cells its walls hide.

The floor beside a wall the scan lines cross reads short: the line (as wide as the beam)
straddles the edge and the centre detector's kernel carries the step along the line. The
floor counts only beyond ``wall_band_mm + bias_per_depth ×`` its depth from such a wall (the
simulator, beech 0.2 mm deep, tune seeds 0 and 2: 28–45 µm short within 0.1 mm, 10–35 µm at
0.1–0.15 mm, 3–19 µm at 0.15–0.2 mm, within 8 µm beyond; 0.5 mm deep: 56–116 µm within
0.1 mm). A wall parallel to the lines (its normal within 45° of across them) is not
straddled: its zone is ``parallel_band_mm`` or ``parallel_per_depth ×`` the depth, the larger
(the wall the camera faces, as wide in its image as the depth × tan 25°, merges with the
floor's line: 0.5 mm deep, 62 µm short 0.2–0.25 mm from it, within 10 µm beyond 0.3 mm;
0.2 mm deep, within −6 … +5 µm from 0.05 mm on, where the crossed walls' floor reads short).
A parallel wall facing the camera (its normal into the pocket towards the camera's side) also
keeps ``faced_band_mm``: on a specular blank the camera sees the floor's line mirrored in it
and the lines beside it read short (the simulator, stainless, seed 33, the mirrored light
switched off against on: 8–27 µm short 0.1–0.4 mm from the wall 0.1 mm deep, 11–72 µm
0.1–0.3 mm from it 0.2 mm deep, 34–99 µm 0.1–0.3 mm from it 0.5 mm deep; nothing beyond
0.4 mm). The engraving's maps keep that band (``services.engrave_request.LOOP_DEPTH``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from insitu.marking.engrave_depth import DepthSettings, Outline, PocketCells


def clear(walls: tuple[np.ndarray, ...], depth, s: DepthSettings) -> np.ndarray:
    """Where points (or cells' centres) at ``depth`` mm lie beyond the walls' bias zones:
    ``walls`` their distances to the crossed, the parallel and the faced walls
    (:meth:`Outline.wall_distances`)."""
    depth = np.maximum(depth, 0.0)
    ok = ((walls[0] >= s.wall_band_mm + s.bias_per_depth * depth)
          & (walls[1] >= np.maximum(s.parallel_band_mm, s.parallel_per_depth * depth)))
    return ok & (walls[2] >= s.faced_band_mm) if len(walls) > 2 else ok


def trusted_depth(walls: tuple[np.ndarray, ...], s: DepthSettings) -> np.ndarray:
    """The depth (mm) down to which points at distances ``walls`` (as :func:`clear` takes
    them) stay beyond the bias zones; 0 within a band."""
    crossed = (walls[0] - s.wall_band_mm) / s.bias_per_depth
    parallel = np.where(walls[1] >= s.parallel_band_mm, walls[1] / s.parallel_per_depth, 0.0)
    out = np.maximum(np.minimum(crossed, parallel), 0.0)
    return np.where(walls[2] >= s.faced_band_mm, out, 0.0) if len(walls) > 2 else out


MAX_CROSSING = 0.02
"""The most the points may spread across the lines' direction, as a share of along it
(variances about each line's mean): parallel lines ≈ 0; two passes 16° apart 0.02, 45°
apart 0.17."""


def line_direction(xy: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(2,) unit direction of the scan lines: the principal axis of the points ``xy``
    (N, 2) about their own line's mean (``line`` (N,)); (0, 1) with too few points."""
    return line_axes(xy, line)[0]


def line_axes(xy: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, float]:
    """:func:`line_direction` and the points' variance across it as a share of along it
    (0 for parallel straight lines; :data:`MAX_CROSSING`)."""
    if len(xy) < 3:
        return np.array([0.0, 1.0]), 0.0
    inv = np.unique(line, return_inverse=True)[1].ravel()
    n = np.bincount(inv).astype(float)
    c = xy - np.column_stack([np.bincount(inv, xy[:, k]) / n for k in (0, 1)])[inv]
    w, vecs = np.linalg.eigh(c.T @ c)
    v = vecs[:, -1]
    return v * np.sign(v[1] if abs(v[1]) > 1e-9 else v[0]), float(w[0] / max(w[1], 1e-12))


def viewpoints(rig) -> np.ndarray:
    """(2, 3) world mm: where a rig (``rig.camera``, ``rig.head``) sees a pocket from: the
    camera's centre and the head's pivot, for :func:`unreachable`."""
    return np.array([rig.camera.centre_world, [0.0, 0.0, rig.head.pivot_height_mm]])


def unreachable(cells: PocketCells, depth: np.ndarray, outline: Outline,
                viewpoints: np.ndarray) -> np.ndarray:
    """(ny, nx) bool: cells of the pocket that a ray to one of ``viewpoints`` (K, 3) world mm
    leaves through a wall: from the floor at ``depth`` (mm below the top) it must rise out of
    the pocket before it passes the outline."""
    gx, gy = cells.centres()
    out = np.zeros(cells.shape, bool)
    inside = cells.inside & (depth > 0)
    if not inside.any():
        return out
    px, py, d = gx[inside], gy[inside], depth[inside]
    blocked = np.zeros(len(px), bool)
    for vp in np.asarray(viewpoints, float):
        h = np.hypot(vp[0] - px, vp[1] - py)
        rise = max(vp[2], 1.0)                       # the top is far below the viewpoint
        reach = d * h / rise                         # horizontal run until the top's height
        u = np.column_stack([vp[0] - px, vp[1] - py]) / np.maximum(h, 1e-9)[:, None]
        for t in np.linspace(0.0, 1.0, 9)[1:]:
            qx, qy = px + u[:, 0] * reach * t, py + u[:, 1] * reach * t
            blocked |= outline.distance(qx, qy) <= 0
    out[inside] = blocked
    return out


WALL_STEP_MM = 0.01
"""The step of :func:`wall_extent`'s search, mm."""


def wall_extent(inward_mm: np.ndarray, depth: np.ndarray) -> float:
    """How far (mm) from the outline a pocket's walls slope down to its floor, measured: the
    points inside it at ``inward_mm`` (N,) from the outline with their ``depth`` (N,) mm; the
    floor's level is the median depth of the innermost quarter, and the extent ``t`` the one
    whose ramp ``level × min(inward / t, 1)`` lies closest (least absolute deviations) to the
    points within ``t`` + 0.1 mm, searched every :data:`WALL_STEP_MM` up to the innermost
    quarter. A wall's points at a fraction of the floor's depth pass the bias zones, set by
    the depth around them (the simulated plate, walls sloping over 0.3 mm: 0.1 mm pocket 10 µm
    short of its floor); straight walls measure ≈ 0.03 mm, within the zones."""
    if len(depth) < 20:
        return 0.0
    inner = np.quantile(inward_mm, 0.75)
    level = np.median(depth[inward_mm >= inner])
    steps = np.arange(WALL_STEP_MM, inner + 1e-9, WALL_STEP_MM)
    if level <= 0 or len(steps) == 0:
        return 0.0
    near = inward_mm < steps[-1] + 0.1
    r, d = inward_mm[near], depth[near]
    cost = np.abs(d[None, :] - level * np.minimum(r[None, :] / steps[:, None], 1.0)).sum(1)
    return float(steps[int(np.argmin(cost))])


def wall_feet(walls: tuple[np.ndarray, ...], depth: np.ndarray) -> np.ndarray:
    """(2,) mm: :func:`wall_extent` of the walls the scan lines cross and of those parallel to
    them, each from the floor's points (``walls`` their distances as :func:`clear` takes
    them, ``depth`` (N,) mm) nearer to that kind of wall. Apart: beside a crossed wall the
    line straddling the edge reads the floor short over ≈ 0.15 mm, a ramp its zone already
    covers, while a parallel wall's profile is the wall's own (the simulated plate, seed 45:
    straight walls, the crossed walls' feet 0.12–0.17 mm, the parallel ones' 0.01–0.17 mm,
    the depths unmoved; walls sloping over 0.3 mm, 0.17–0.31 and 0.31–0.35 mm)."""
    nearer = walls[0] <= walls[1]
    return np.array([wall_extent(walls[0][nearer], depth[nearer]),
                     wall_extent(walls[1][~nearer], depth[~nearer])])


def beyond_feet(walls: tuple[np.ndarray, ...], feet: np.ndarray) -> np.ndarray:
    """Where points (or cells' centres) at distances ``walls`` lie beyond the crossed and the
    parallel walls' measured feet (:func:`wall_feet`)."""
    return (walls[0] >= feet[0]) & (walls[1] >= feet[1])
