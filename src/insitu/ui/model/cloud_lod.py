"""Which points of a large cloud the 3-D view draws (no OpenGL): the cloud sorted into xy
tiles (stable, so each tile keeps the scan order a software renderer is fast on), the tiles
inside the view (clip-space test of their boxes), and an even thinning of those — every
k-th point, k the same for all — that keeps a frame within a budget of points."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TILES_PER_SIDE = 32
MAX_STRIDE = 170            # GL's attribute stride limit (2048 bytes) over 12-byte points


@dataclass(frozen=True)
class TiledCloud:
    """``points``: (N, 3) float32 mm sorted by tile; ``order``: (N,) the input index of
    each; ``starts``, ``ends``: (T,) the tiles' index ranges; ``lo``, ``hi``: (T, 3) their
    boxes, mm."""

    points: np.ndarray
    order: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, tiles: int = TILES_PER_SIDE) -> "TiledCloud":
        """Tile (N, 3) mm points into ``tiles`` × ``tiles`` cells of their xy box."""
        pts = np.asarray(points, np.float64).reshape(-1, 3)
        if len(pts) == 0:
            z = np.zeros((0, 3))
            return cls(pts.astype(np.float32), np.zeros(0, np.int64), np.zeros(0, np.int64),
                       np.zeros(0, np.int64), z, z)
        lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
        cell = np.clip(((pts[:, :2] - lo) / np.maximum(hi - lo, 1e-9) * tiles).astype(int),
                       0, tiles - 1)
        key = cell[:, 1] * tiles + cell[:, 0]
        order = np.argsort(key, kind="stable")
        key, sorted_pts = key[order], pts[order]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        ends = np.r_[starts[1:], len(key)]
        return cls(sorted_pts.astype(np.float32), order, starts, ends,
                   np.minimum.reduceat(sorted_pts, starts), np.maximum.reduceat(sorted_pts, starts))

    def visible(self, mvp: np.ndarray) -> np.ndarray:
        """(T,) bool: tiles whose box is not wholly outside one clip plane of ``mvp``
        ((4, 4) world → clip, row-major); conservative (a box near a corner may be kept)."""
        if len(self.starts) == 0:
            return np.zeros(0, bool)
        corners = np.stack([np.where(np.array([i & 1, i & 2, i & 4], bool), self.hi, self.lo)
                            for i in range(8)], 1)                     # (T, 8, 3)
        clip = corners @ np.asarray(mvp, np.float64)[:3, :3].T + np.asarray(mvp)[:3, 3]
        w = corners @ np.asarray(mvp, np.float64)[3, :3] + mvp[3, 3]
        out = np.zeros(len(self.starts), bool)
        for axis in range(3):
            c = clip[..., axis]
            out |= (c > w).all(1) | (c < -w).all(1)
        return ~out

    def visible_runs(self, mvp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(starts, ends) of the visible tiles, adjacent ones merged into one run."""
        vis = self.visible(mvp)
        s, e = self.starts[vis], self.ends[vis]
        if len(s) == 0:
            return s, e
        new = np.r_[True, s[1:] != e[:-1]]
        return s[new], np.r_[e[np.flatnonzero(new)[1:] - 1], e[-1]]


def draw_ranges(starts: np.ndarray, ends: np.ndarray, budget: int
                ) -> tuple[int, np.ndarray, np.ndarray]:
    """(k, first, count): draw every k-th point of the ranges [starts, ends) — the points
    j·k for j in [first_i, first_i + count_i) — with k the least (≤ :data:`MAX_STRIDE`)
    that keeps the total at most ``budget``."""
    starts, ends = np.asarray(starts, np.int64), np.asarray(ends, np.int64)
    total = int((ends - starts).sum())
    k = int(min(max(-(-total // max(budget, 1)), 1), MAX_STRIDE))
    first = -(-starts // k)
    count = np.maximum(-(-ends // k) - first, 0)
    keep = count > 0
    return k, first[keep], count[keep]
