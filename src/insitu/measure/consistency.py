"""The 3-D check across lines: neighbouring lines of a scan (a fraction of a millimetre apart)
see nearly the same surface, so a point that none of them confirms is a wrong line — a ghost,
a secondary reflection, a peak of the wrong level — not the surface.

For each point, the nearest points of the lines one and two steps away in the scan (in x, y)
predict its height three ways: interpolated between the line before and the line after, and
extrapolated from the two lines on either side (so the last line on a part's top, beside a
wall, is confirmed by the top's own lines). A point is kept when one prediction agrees within
``k_sigma`` of that prediction's noise sigmas; a point's sigma is measured on the scan itself
(robustly, from the two-sided predictions). Points no neighbouring line can judge (a line alone, holes on both
sides) are kept.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def cross_line_inliers(points: np.ndarray, line: np.ndarray, k_sigma: float = 5.0,
                       min_tolerance_mm: float = 0.05) -> np.ndarray:
    """(N,) bool: the points (N, 3) mm confirmed by their neighbouring lines. ``line``: (N,)
    the line (frame index) each came from; lines follow each other in the order of their
    indices, as a scan draws them."""
    n = len(points)
    keep = np.ones(n, bool)
    order = np.argsort(line, kind="stable")
    xy, z, ln = points[order, :2], points[order, 2], line[order]
    starts = np.r_[0, np.flatnonzero(np.diff(ln)) + 1, n]
    if len(starts) < 4:
        return keep
    trees = [cKDTree(xy[a:b]) for a, b in zip(starts[:-1], starts[1:])]
    reach = 2.5 * _line_spacing(xy, starts, trees)
    nearest = {o: _nearest_on_line(xy, starts, trees, o, reach) for o in (-2, -1, 1, 2)}
    predictions = [_predict(xy, z, nearest[-1], nearest[1]),        # between the two sides
                   _predict(xy, z, nearest[-2], nearest[-1]),       # from the lines before
                   _predict(xy, z, nearest[1], nearest[2])]         # from the lines after
    between = predictions[0] - z
    judged = np.isfinite(between)
    if judged.sum() < 10:
        return keep
    # the residual of a prediction between two lines has 1.5 × a point's noise variance, of
    # one extrapolated from two lines on one side (2 z1 − z2) 6 ×
    sigma = 1.4826 * np.median(np.abs(between[judged])) / np.sqrt(1.5)
    tol = np.maximum(k_sigma * sigma * np.sqrt([1.5, 6.0, 6.0]), min_tolerance_mm)
    residual = np.stack([np.abs(p - z) for p in predictions])
    judged = np.isfinite(residual).any(axis=0)
    agrees = (np.nan_to_num(residual, nan=np.inf) <= tol[:, None]).any(axis=0)
    keep[order] = ~judged | agrees
    return keep


def _line_spacing(xy: np.ndarray, starts: np.ndarray, trees: list, per_line: int = 50
                  ) -> float:
    """Median distance, mm, from points of a line to the nearest points of the next line."""
    d = []
    for r in range(len(trees) - 1):
        a, b = starts[r], starts[r + 1]
        d.append(trees[r + 1].query(xy[np.linspace(a, b - 1, min(per_line, b - a)).astype(int)])[0])
    return float(np.median(np.concatenate(d)))


def _nearest_on_line(xy: np.ndarray, starts: np.ndarray, trees: list, offset: int,
                     reach: float) -> np.ndarray:
    """(N,) index of each point's nearest point on the line ``offset`` lines away, within
    ``reach`` mm in x, y; −1 where there is none."""
    out = np.full(len(xy), -1)
    for r in range(max(0, -offset), min(len(trees), len(trees) - offset)):
        a, b = starts[r], starts[r + 1]
        d, j = trees[r + offset].query(xy[a:b], distance_upper_bound=reach)
        ok = np.isfinite(d)
        out[a:b][ok] = starts[r + offset] + j[ok]
    return out


def _predict(xy: np.ndarray, z: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) height at each point from the straight line through points ``a`` and ``b``
    (indices, −1: none → NaN), taken at the point's position projected on it in x, y."""
    ok = (a >= 0) & (b >= 0)
    out = np.full(len(z), np.nan)
    i, ia, ib = np.flatnonzero(ok), a[ok], b[ok]
    ab = xy[ib] - xy[ia]
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.einsum("ij,ij->i", xy[i] - xy[ia], ab) / np.where(L2 > 0, L2, 1.0)
    out[i] = np.where(L2 > 0, z[ia] + t * (z[ib] - z[ia]), np.nan)
    return out
