"""The layers of an engraving round as mark paths: layer j (1 …) hatches the pocket where the
cells still get a j-th pass, the hatch turned by 90° from layer to layer and shifted across
its lines (no ridge of one layer's lines lies on the last's), each line cut where it enters
and leaves those cells; every point at the height the floor is at when its layer begins, so
the focus follows the floor down.
"""

from __future__ import annotations

import numpy as np

from insitu.marking.engrave_depth import PocketCells
from insitu.marking.engrave_plan import owners
from insitu.patterns.fill import hatch_segments

_SAMPLE_MM = 0.005      # where a hatch line is cut into runs, to this
_STEP_MM = 0.5          # points along a run (the top may curve)
_SHIFT = 0.381966       # successive layers' hatch offsets, in hatch distances (golden)


def layer_runs(contours, cells: PocketCells, passes: np.ndarray, layer: int, hatch_mm: float,
               angle_deg: float, shift: float) -> list[np.ndarray]:
    """(2, 2) world x, y segments of layer ``layer``: the pocket's hatch at ``angle_deg``,
    moved ``shift`` hatch distances across its lines, kept where the cell under it has
    ``passes`` ≥ ``layer``; back and forth line by line."""
    a = np.radians(angle_deg)
    normal = np.array([-np.sin(a), np.cos(a)]) * shift * hatch_mm
    k, x0, x1, y, rot = hatch_segments([np.asarray(c) - normal for c in contours], hatch_mm,
                                       angle_deg)
    r_own, c_own = owners(cells)
    runs: list[np.ndarray] = []
    for i in range(len(k)):
        n = max(int(np.ceil((x1[i] - x0[i]) / _SAMPLE_MM)), 1)
        xs = np.linspace(x0[i], x1[i], n + 1)
        pts = np.column_stack([xs, np.full(n + 1, y[i])]) @ rot.T + normal
        row, col = cells.index(pts[:, 0], pts[:, 1])
        on = passes[r_own[row, col], c_own[row, col]] >= layer
        if not on.any():
            continue
        edges = np.flatnonzero(np.diff(np.r_[0, on.astype(int), 0]))
        for s, e in zip(edges[::2], edges[1::2]):
            seg = pts[[s, e - 1]] if e - 1 > s else None
            if seg is not None:
                runs.append(seg[::-1] if k[i] % 2 else seg)
    return runs


def layer_paths(contours, cells: PocketCells, passes: np.ndarray, hatch_mm: float,
                top_z, floor_mm: np.ndarray, rate_mm: np.ndarray, first_layer: int
                ) -> list[tuple[int, np.ndarray]]:
    """Every layer of a round as (layer, (N, 3) path) in marking order. ``top_z``: (M, 2) →
    (M,) the top's height there (the measured surface before engraving); ``floor_mm`` and
    ``rate_mm`` (ny, nx): each cell's depth now and per pass; ``first_layer``: the number of
    layers marked before this round (the hatch's turn and shift go on from there)."""
    r_own, c_own = owners(cells)
    out: list[tuple[int, np.ndarray]] = []
    for j in range(1, int(passes.max(initial=0)) + 1):
        count = first_layer + j
        runs = layer_runs(contours, cells, passes, j, hatch_mm, 90.0 * (count % 2),
                          (count * _SHIFT) % 1.0)
        for seg in runs:
            length = float(np.linalg.norm(seg[1] - seg[0]))
            n = max(int(np.ceil(length / _STEP_MM)), 1)
            xy = seg[0] + np.linspace(0.0, 1.0, n + 1)[:, None] * (seg[1] - seg[0])
            row, col = cells.index(xy[:, 0], xy[:, 1])
            r, c = r_own[row, col], c_own[row, col]
            z = top_z(xy) - floor_mm[r, c] - (j - 1) * rate_mm[r, c]
            out.append((j, np.column_stack([xy, z])))
    return out


def passes_given(paths: list[np.ndarray], done: np.ndarray, cells: PocketCells,
                 planned: np.ndarray) -> np.ndarray:
    """(ny, nx) passes each cell had of a round that may have stopped early: its planned
    passes times the share of its hatch length the ``done`` (bool per path) paths marked."""
    r_own, c_own = owners(cells)
    total = np.zeros(cells.shape)
    marked = np.zeros(cells.shape)
    for path, ok in zip(paths, done):
        d = np.linalg.norm(np.diff(path[:, :2], axis=0), axis=1)
        n = np.maximum(np.ceil(d / 0.01).astype(int), 1)
        for a, b, seg, k in zip(path[:-1, :2], path[1:, :2], d, n):
            t = (np.arange(k) + 0.5) / k
            pts = a + t[:, None] * (b - a)
            row, col = cells.index(pts[:, 0], pts[:, 1])
            np.add.at(total, (r_own[row, col], c_own[row, col]), seg / k)
            if ok:
                np.add.at(marked, (r_own[row, col], c_own[row, col]), seg / k)
    share = np.where(total > 0, marked / np.where(total > 0, total, 1), 0.0)
    return planned * share
