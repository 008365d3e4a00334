"""Point-to-plane ICP restricted to a part lying flat: a turn about z and a shift in x, y, z
(4 degrees of freedom), so a fit can never tilt the part off the table. Poses are
:data:`insitu.geometry.pose.Pose4`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from insitu.geometry.pose import Pose4, apply, rot_z


@dataclass(frozen=True)
class Fit:
    """How well source points fit the target after ICP: ``pose``; ``fitness``, the fraction of
    the source points within ``inlier_mm`` of the target's surface; ``rmse_mm`` of those
    inliers' point-to-plane distances."""

    pose: Pose4
    fitness: float
    rmse_mm: float


def residuals(src: np.ndarray, tree: cKDTree, normals: np.ndarray, targets: np.ndarray,
              reach_mm: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(found (N,) bool, nearest target index (N,), signed point-to-plane distance (N,)) of
    each source point whose nearest target point lies within ``reach_mm``."""
    dist, idx = tree.query(src, distance_upper_bound=reach_mm)
    found = np.isfinite(dist)
    idx = np.where(found, idx, 0)
    r = np.einsum("ij,ij->i", src - targets[idx], normals[idx])
    return found, idx, r


def icp_flat(src: np.ndarray, targets: np.ndarray, normals: np.ndarray, tree: cKDTree,
             pose: Pose4, reach_mm: tuple[float, ...], iterations: int = 12,
             inlier_mm: float = 0.3) -> Fit:
    """Refine ``pose`` mapping ``src`` (N, 3) onto the surface sampled by ``targets`` (M, 3)
    with unit ``normals`` (M, 3) (``tree``: their KD-tree): Gauss-Newton on the point-to-plane
    distances of the pairs closer than each ``reach_mm`` in turn (coarse to fine), Huber
    weights at ``inlier_mm``. Returns the fit scored at ``inlier_mm``. A fit that comes
    back to where it was two steps before at the same reach (its pairs flip between two
    sets) would only alternate to the end of that reach's iterations: it takes the pose
    they would end on at once."""
    angle, t = float(pose[0]), np.asarray(pose[1], np.float64).copy()
    for reach in reach_mm:
        back: list[Pose4] = []                 # the poses one and two steps back
        for k in range(iterations):
            p = src @ rot_z(angle).T + t
            found, idx, r = residuals(p, tree, normals, targets, reach)
            if found.sum() < 10:
                break
            p, r, n = p[found], r[found], normals[idx[found]]
            c = p.mean(axis=0)
            q = p - c
            J = np.column_stack([n[:, 1] * q[:, 0] - n[:, 0] * q[:, 1], n])
            w = np.minimum(1.0, inlier_mm / np.maximum(np.abs(r), 1e-12))
            A = J.T @ (J * w[:, None]) + 1e-9 * np.eye(4)
            x = np.linalg.solve(A, -J.T @ (w * r))
            d, dt = x[0], x[1:]
            Rd = rot_z(d)
            back = [(angle, t), *back[:1]]
            angle, t = angle + d, Rd @ (t - c) + c + dt
            if abs(d) < 1e-7 and np.linalg.norm(dt) < 1e-5:
                break
            if len(back) == 2 and _same(back[1], (angle, t)):    # a cycle of two poses
                angle, t = back[0] if (iterations - k - 1) % 2 else (angle, t)
                break
    return score((angle, t), src, targets, normals, tree, inlier_mm)


def _same(a: Pose4, b: Pose4) -> bool:
    """Whether two poses agree to rounding (1e-12 rad, 1e-9 mm)."""
    return abs(a[0] - b[0]) < 1e-12 and bool(np.abs(a[1] - b[1]).max() < 1e-9)


def score(pose: Pose4, src: np.ndarray, targets: np.ndarray, normals: np.ndarray,
          tree: cKDTree, inlier_mm: float) -> Fit:
    """The fit of ``src`` mapped by ``pose``: a point is an inlier when a target point lies
    within 4 × ``inlier_mm`` and its surface within ``inlier_mm``."""
    found, _, r = residuals(apply(pose, src), tree, normals, targets, 4 * inlier_mm)
    ok = found & (np.abs(r) <= inlier_mm)
    rmse = float(np.sqrt(np.mean(r[ok] ** 2))) if ok.any() else float("inf")
    return Fit(pose, float(ok.mean()) if len(ok) else 0.0, rmse)
