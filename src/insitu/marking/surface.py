"""The measured surface seen from above: robust local height and slope at any (x, y).

A :class:`Surface` wraps a point cloud (world frame, mm) in a 2-D KD-tree over x, y. At a query
point it takes the k nearest cloud points within the hole radius and fits a plane robustly:
the query point's level is that of its 6 nearest neighbours; points that a surface of 60°
slope could not reach from them (a second level across a step) are rejected, a plane is
fitted to the rest (a small ridge keeps its slope near 0 across a direction the neighbours do
not span, e.g. all on one scan line), points more than 3 RMS off that plane are rejected once
more, and the plane is refitted. The plane's value at the query point is the height (exact on
planes, tilted or not); its gradient gives the slope. Where the neighbourhood straddles two
levels — a gap in height that no surface of 60° spans between the nearest points of the two
(a step leaves one where the scan lines break; a measured slope has points all the way up) —
the point takes its nearest neighbours' level and that level's slope: a vertical step has no
surface to mark on, the projection splits paths where they drop from one level to the other
(:func:`level_jumps`), while a steep surface (a chamfer, the flank of a curved part) keeps
its steep slope.

Beside a step the camera loses the foot of the wall behind the top edge and the upper level's
lines stop short of the edge: between the two levels lies a strip neither measured. A point
there is ``unmeasured``: across the wall (from its level towards the other), its level's
nearest measured point — among those beside it along the wall, within the coverage spacing —
lies more than half the point spacing behind it (a measured point stands for ± half the
spacing around it) where the levels' facing points are a spacing apart; less as they lie
further apart (a quarter at 1.5 spacings: the step block's upper level 0.019 mm over its edge
and a target 0.076 mm beyond that, 0.47 spacing, was marked 2 mm high). Where points were lost
there (the facing points more than 1.5 spacings apart), the wall may be anywhere in the strip
and a level's last point itself may lie over the edge: a point within half a spacing of it is
unmeasured too. Nothing is marked there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from insitu.errors import MeasurementError
from insitu.formats.pointcloud import PointCloud

_Z_FLOOR_MM = 0.02          # never reject points closer than this to the robust estimate
_RIDGE = 0.02               # ridge on the slope terms: as if spread ± this × radius
_LEVEL_SLOPE = np.tan(np.radians(60.0))   # steeper jumps within a neighbourhood: two levels
_NEAR = 6                   # nearest neighbours that tell a query point's level
_LOST = 1.5                 # levels farther apart across a wall (× point spacing): points lost


@dataclass(frozen=True)
class SurfaceSample:
    """Per query point (M,): height z (mm, NaN where no cloud point within the hole radius),
    gradient (M, 2) dz/dx, dz/dy of the robust plane, slope_deg of the local surface (walls
    included), gap_mm to the nearest cloud point (inf when none within the hole radius) and
    the number of neighbours used; ``unmeasured`` (M,) bool: in the strip between two levels
    that neither measured (see the module docstring)."""

    z: np.ndarray
    grad: np.ndarray
    slope_deg: np.ndarray
    gap_mm: np.ndarray
    n_used: np.ndarray
    unmeasured: np.ndarray


def level_jumps(xyz: np.ndarray) -> np.ndarray:
    """(N - 1,) bool: between consecutive points (N, 3) of a path the surface drops or rises
    more steeply than a surface could and still be one level (a step's wall)."""
    d = np.diff(np.asarray(xyz, np.float64), axis=0)
    return np.abs(d[:, 2]) > _Z_FLOOR_MM + _LEVEL_SLOPE * np.hypot(d[:, 0], d[:, 1])


class Surface:
    """``points``: (N, 3) mm or a PointCloud; ``region`` (x0, x1, y0, y1) keeps only points
    inside (speed on big clouds); ``k`` neighbours per query; ``hole_radius_mm``: no cloud point
    within this distance (in x, y) means a hole (default: 4 × the coverage spacing, at least
    3 × the point spacing)."""

    def __init__(self, points: np.ndarray | PointCloud, region=None, k: int = 16,
                 hole_radius_mm: float | None = None):
        pts = np.asarray(points.points if isinstance(points, PointCloud) else points, np.float64)
        pts = pts.reshape(-1, 3)
        pts = pts[np.isfinite(pts).all(1)]
        if region is not None:
            x0, x1, y0, y1 = region
            pts = pts[(pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)]
        if len(pts) < 3:
            raise MeasurementError("the point cloud has fewer than 3 points under the pattern; "
                                   "scan the region where the pattern goes")
        self.points = pts
        self.k = int(k)
        self.tree = cKDTree(pts[:, :2], balanced_tree=False, compact_nodes=False)
        self.spacing_mm, self.coverage_mm = _spacing(self.tree, pts)
        self.hole_radius_mm = float(hole_radius_mm if hole_radius_mm is not None
                                    else max(4 * self.coverage_mm, 3 * self.spacing_mm))
        self._padded = tuple(np.append(pts[:, i], 0.0) for i in range(3))

    def sample(self, xy: np.ndarray, k: int | None = None, chunk: int = 8192) -> SurfaceSample:
        """Robust local plane at each (M, 2) point, mm. See the module docstring. Works in
        chunks of ``chunk`` points (cache-sized)."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        k = min(int(k or self.k), len(self.points))
        parts = [self._sample(xy[i:i + chunk], k) for i in range(0, len(xy), chunk)]
        if not parts:
            e = np.zeros(0)
            return SurfaceSample(e, np.zeros((0, 2)), e, e, e.astype(int), e.astype(bool))
        return SurfaceSample(*(np.concatenate([getattr(p, f) for p in parts])
                               for f in SurfaceSample.__dataclass_fields__))

    def _sample(self, xy: np.ndarray, k: int) -> SurfaceSample:
        d, idx = self.tree.query(xy, k=k, distance_upper_bound=self.hole_radius_mm, workers=1)
        d, idx = d.reshape(len(xy), k), idx.reshape(len(xy), k)
        valid = np.isfinite(d)
        px, py, pz = self._padded                              # 0 at the missing index
        dx = np.where(valid, px[idx] - xy[:, :1], 0.0)
        dy = np.where(valid, py[idx] - xy[:, 1:], 0.0)
        z = pz[idx]
        r_k = np.where(valid, d, 0.0).max(1)                   # neighbourhood radius
        n_valid = valid.sum(1)
        fit = _PlaneFit(dx, dy, z, ridge=n_valid * (_RIDGE * r_k) ** 2 + 1e-12)
        # 1: the query point's level (_level_of its nearest neighbours): across a step, the
        #    neighbours on its side of the gap; elsewhere those a surface of slope
        #    _LEVEL_SLOPE can reach from the level's height
        r_near = np.where(valid[:, :_NEAR], d[:, :_NEAR], 0.0).max(1)
        ref, cut, upper = _level_of(z, valid, dx, dy)
        reach = np.abs(z - ref[:, None]) <= _Z_FLOOR_MM + _LEVEL_SLOPE * (
            np.where(valid, d, 0.0) + r_near[:, None])
        same_side = (z > cut[:, None]) == upper[:, None]
        keep = valid & reach & np.where(np.isfinite(cut)[:, None], same_side, True)
        coef = fit(keep)
        # 2: reject points more than 3 RMS off that plane; refit the rows that changed
        res = np.abs(z - (coef[:, :1] + coef[:, 1:2] * dx + coef[:, 2:] * dy))
        n_keep = keep.sum(1)
        rms = np.sqrt(np.einsum("ij,ij->i", keep, res * res) / np.maximum(n_keep, 1))
        keep2 = keep & (res <= np.maximum(3.0 * rms, _Z_FLOOR_MM)[:, None])
        redo = (keep2.sum(1) != n_keep) & (keep2.sum(1) >= 3)
        if redo.any():
            coef[redo] = fit(keep2, rows=redo)
            keep[redo] = keep2[redo]
        n_keep = keep.sum(1)
        grad = coef[:, 1:]
        slope = np.degrees(np.arctan(np.hypot(grad[:, 0], grad[:, 1])))
        zq = np.where(n_valid > 0, coef[:, 0], np.nan)
        grad[n_valid == 0] = np.nan
        slope[n_valid == 0] = np.nan
        unmeasured = np.zeros(len(xy), bool)
        step = np.isfinite(cut)
        if step.any():
            unmeasured[step] = self._unmeasured(xy[step], cut[step], upper[step])
        return SurfaceSample(zq, grad, slope, d[:, 0], n_keep, unmeasured)

    def _unmeasured(self, xy: np.ndarray, cut: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """(M,) bool: query points (M, 2) beside a step (levels split at height ``cut``, the
        point's on the ``upper`` one or not) that lie in the strip between the levels that
        neither measured. The direction across the wall is from the centroid of the point's
        level to that of the other among its 4 k nearest cloud points."""
        k = min(4 * self.k, len(self.points))
        d, idx = self.tree.query(xy, k=k, distance_upper_bound=self.hole_radius_mm, workers=1)
        d, idx = d.reshape(len(xy), k), idx.reshape(len(xy), k)
        valid = np.isfinite(d)
        px, py, pz = self._padded
        dx = np.where(valid, px[idx] - xy[:, :1], 0.0)
        dy = np.where(valid, py[idx] - xy[:, 1:], 0.0)
        own = valid & ((pz[idx] > cut[:, None]) == upper[:, None])
        other = valid & ~own

        def centroid(m):
            n = np.maximum(m.sum(1), 1)
            return np.column_stack([(dx * m).sum(1) / n, (dy * m).sum(1) / n])
        n = centroid(other) - centroid(own)
        norm = np.hypot(n[:, 0], n[:, 1])
        n /= np.maximum(norm, 1e-12)[:, None]
        across = dx * n[:, :1] + dy * n[:, 1:]                # towards the other level
        along = np.abs(dy * n[:, :1] - dx * n[:, 1:])
        beside = along <= self.coverage_mm
        edge = np.where(own & beside, across, -np.inf).max(1)     # the level's last point
        foot = np.where(other & beside, across, np.inf).min(1)    # the other's first, mm
        sp, gap = self.spacing_mm, foot - edge
        need = np.where(gap > _LOST * sp, 0.5 * sp, np.clip(0.5 * gap - sp, -0.5 * sp, 0.0))
        return other.any(1) & (norm > 0) & (edge < need)

    def quadric(self, centre: np.ndarray, radius_mm: float, max_points: int = 20000
                ) -> np.ndarray | None:
        """Least-squares z = c0 + c1 dx + c2 dy + c3 dx² + c4 dx dy + c5 dy² about ``centre``
        (2,) over the cloud within ``radius_mm``; (6,) or None when too few points."""
        ids = np.asarray(self.tree.query_ball_point(np.asarray(centre, float), radius_mm))
        if len(ids) < 12:
            return None
        if len(ids) > max_points:
            ids = np.random.default_rng(0).choice(ids, max_points, replace=False)
        p = self.points[ids]
        dx, dy = p[:, 0] - centre[0], p[:, 1] - centre[1]
        A = np.column_stack([np.ones_like(dx), dx, dy, dx * dx, dx * dy, dy * dy])
        coef, *_ = np.linalg.lstsq(A, p[:, 2], rcond=None)
        return coef


def _spacing(tree: cKDTree, pts: np.ndarray) -> tuple[float, float]:
    """Point spacing (median nearest-neighbour distance, x-y) and coverage spacing
    (1/√density from the 8th neighbour: how far apart scan lines are), mm."""
    rng = np.random.default_rng(0)
    sub = pts[rng.choice(len(pts), min(len(pts), 20000), replace=False), :2]
    k = min(9, len(pts))
    d, _ = tree.query(sub, k=k, workers=-1)
    d1 = d[:, 1]
    pos = d1[d1 > 0]
    spacing = float(np.median(pos)) if len(pos) else 1e-3
    coverage = float(np.median(d[:, -1]) * np.sqrt(np.pi / (k - 1)))
    return max(spacing, 1e-3), max(coverage, spacing, 1e-3)


def _level_of(z: np.ndarray, valid: np.ndarray, dx: np.ndarray, dy: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The level a query point is on, from its neighbours (rows of (M, k) ``z``, offsets
    ``dx``, ``dy``, sorted by distance). They are split at their largest gap in z; it is a
    step (two levels) when that gap is larger than a _LEVEL_SLOPE surface rises over the
    shortest distance in x, y between the two groups — a measured slope has points all the
    way up, a wall leaves a gap where the lines break. The level is the nearest neighbour's,
    unless that one stands alone among the _NEAR nearest (an outlier). Returns per row: its
    height (median of its level's near neighbours), the ``cut`` between the levels (NaN: one
    level) and whether the point's level is the ``upper`` one."""
    rows = np.arange(len(z))
    zv = np.where(valid, z, np.nan)
    zs = np.sort(zv, axis=1)                                  # NaN last
    gaps = np.nan_to_num(np.diff(zs, axis=1), nan=-np.inf)
    j = np.argmax(gaps, axis=1)
    gap = gaps[rows, j]
    cut = 0.5 * (zs[rows, j] + zs[rows, np.minimum(j + 1, zs.shape[1] - 1)])
    hi = valid & (z > cut[:, None])
    lo = valid & ~hi
    d2 = (dx[:, :, None] - dx[:, None, :]) ** 2 + (dy[:, :, None] - dy[:, None, :]) ** 2
    across = np.where(lo[:, :, None] & hi[:, None, :], d2, np.inf).min(axis=(1, 2))
    split = np.isfinite(gap) & (gap > _Z_FLOOR_MM + _LEVEL_SLOPE * np.sqrt(across))
    cut = np.where(split, cut, np.nan)
    near = valid[:, :_NEAR]
    zn = np.where(near, z[:, :_NEAR], np.nan)
    upper = zn[:, 0] > cut
    mine = near & ((zn > cut[:, None]) == upper[:, None])
    alone = split & (mine.sum(1) < 2)
    upper[alone] = ~upper[alone]
    mine[alone] = (near & ~mine)[alone]
    ref = _masked_median(z[:, :_NEAR], np.where(split[:, None], mine, near))
    return ref, cut, upper


def _masked_median(a: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Row medians (M,) of (M, k) ``a`` over ``mask`` (NaN for empty rows)."""
    s = np.sort(np.where(mask, a, np.inf), axis=1)
    n = mask.sum(1)
    lo, hi = np.maximum((n - 1) // 2, 0), np.maximum(n // 2, 0)
    rows = np.arange(len(a))
    m = 0.5 * (s[rows, lo] + s[rows, hi])
    return np.where(n > 0, m, np.nan)


class _PlaneFit:
    """Per row of (M, k) offsets dx, dy and heights z (0 where unused): z ≈ c0 + c1 dx + c2 dy
    over the points a weight mask selects; (M, 3). Ridge (M,) on c1, c2."""

    def __init__(self, dx, dy, z, ridge):
        self.cols = [dx, dy, z, dx * dx, dx * dy, dy * dy, dx * z, dy * z]
        self.ridge = ridge

    def __call__(self, w: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        cols, ridge = self.cols, self.ridge
        if rows is not None:
            cols, ridge, w = [c[rows] for c in cols], ridge[rows], w[rows]
        w = w.astype(np.float64)
        sx, sy, sz, sxx, sxy, syy, sxz, syz = (np.einsum("ij,ij->i", w, c) for c in cols)
        A = np.empty((len(w), 3, 3))
        A[:, 0, 0] = np.maximum(w.sum(1), 1e-12)
        A[:, 0, 1] = A[:, 1, 0] = sx
        A[:, 0, 2] = A[:, 2, 0] = sy
        A[:, 1, 1] = sxx + ridge
        A[:, 1, 2] = A[:, 2, 1] = sxy
        A[:, 2, 2] = syy + ridge
        b = np.column_stack([sz, sxz, syz])
        return np.linalg.solve(A, b[..., None])[..., 0]
