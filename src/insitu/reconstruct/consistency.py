"""The 3-D check across lines: neighbouring lines of a scan (a fraction of a millimetre apart)
see nearly the same surface, so a point that none of them confirms is a wrong line — a ghost,
a secondary reflection, a peak of the wrong level — not the surface.

For a point of line i, the nearest points of lines i ± 1 and i ± 2 (in x, y) predict its
height: interpolated between i − 1 and i + 1, and extrapolated from i − 2, i − 1 or from
i + 1, i + 2. Where the surface runs on across the point on both sides (i − 2, i − 1 predict
i + 1 or i + 2, and the reverse) the interpolation between i − 1 and i + 1 decides; beside a
break (a wall on one side) an extrapolation from the lines on the point's own side may confirm
it too (so the last line on a part's top is confirmed by the top's own lines). A point is
removed only when nothing confirms it *and* the surface is known to run on across it on at
least one side: a ghost on one or two lines breaks no such continuity, a wall does, and a line
beside a wall that only one neighbour on its side could confirm is kept.
"Agrees" means within ``k_sigma`` of the prediction's own noise sigma (from the point noise,
which is measured on the scan itself, robustly, from the two-sided predictions).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

MAX_REACH = 4.0
"""How far a straight line through two points predicts, in lengths of the two points' distance
from their middle: far enough for line i − 2, i − 1 to predict line i + 2."""


def cross_line_inliers(points: np.ndarray, line: np.ndarray, k_sigma: float = 5.0,
                       min_tolerance_mm: float = 0.05) -> np.ndarray:
    """(N,) bool: the points (N, 3) mm not contradicted by their neighbouring lines. ``line``:
    (N,) the line (frame index) each came from; lines follow each other in the order of their
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
    near = {o: _nearest_on_line(xy, starts, trees, o, reach) for o in (-2, -1, 1, 2)}
    me = np.arange(n)
    between = _predict(xy, z, near[-1], near[1], me)
    r, f = between
    judged = np.isfinite(r)
    if judged.sum() < 10:
        return keep
    sigma = 1.4826 * float(np.median(np.abs(r[judged] / f[judged])))

    def agree(prediction) -> np.ndarray:
        res, factor = prediction
        return np.nan_to_num(res, nan=np.inf) <= np.maximum(k_sigma * sigma * factor,
                                                            min_tolerance_mm)

    # the surface runs on across the point: the lines on one side predict the other side's
    runs_right = agree(_predict(xy, z, near[-2], near[-1], near[1])) | agree(
        _predict(xy, z, near[-2], near[-1], near[2]))
    runs_left = agree(_predict(xy, z, near[2], near[1], near[-1])) | agree(
        _predict(xy, z, near[2], near[1], near[-2]))
    # one-sided predictions speak only beside a break (a wall on the other side)
    one_sided = agree(_predict(xy, z, near[-2], near[-1], me)) | agree(
        _predict(xy, z, near[1], near[2], me))
    across = runs_right & runs_left & np.isfinite(r)
    confirmed = agree(between) | (~across & one_sided)
    keep[order] = confirmed | ~(runs_right | runs_left)
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


def _predict(xy: np.ndarray, z: np.ndarray, a: np.ndarray, b: np.ndarray, at: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """For each point: |z[at] − the height the straight line through points ``a`` and ``b``
    gives at ``at``'s position| (indices; −1: none → NaN), and that residual's noise in
    units of one point's sigma, √((1 − t)² + t² + 1) at the position t along a → b. NaN
    beyond ``MAX_REACH`` lengths of a → b (lines far apart predict nothing)."""
    ok = (a >= 0) & (b >= 0) & (at >= 0)
    res, factor = np.full(len(z), np.nan), np.full(len(z), np.nan)
    i, ia, ib, it = np.flatnonzero(ok), a[ok], b[ok], at[ok]
    ab = xy[ib] - xy[ia]
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.einsum("ij,ij->i", xy[it] - xy[ia], ab) / np.where(L2 > 0, L2, 1.0)
    good = (L2 > 0) & (np.abs(t - 0.5) <= MAX_REACH)
    res[i] = np.where(good, np.abs(z[ia] + t * (z[ib] - z[ia]) - z[it]), np.nan)
    factor[i] = np.sqrt((1 - t) ** 2 + t ** 2 + 1)
    return res, factor
