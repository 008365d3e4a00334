"""The global step of locating a part (:mod:`insitu.locate.part`): where on the table, turned
how far, from coarse starts refined by a flat ICP — the distinct solutions, scored.

Starts come two ways, on a ``voxel_mm`` grid: a search over turns about z (every
``turn_step_deg``, x, y from the tops' centroids) and FPFH features matched by RANSAC
(``open3d.pipelines.registration``, seeded anew for each run; :mod:`insitu.locate.part`
asks for them where the turn search's best would be refused); each is
refined by a coarse flat ICP, then by point-to-plane ICP of the scan (thinned) onto the dense
reference (:mod:`insitu.locate.flat_icp`). Each distinct solution is scored: ``fitness``
(the scan's points within ``inlier_mm`` of the reference's surface), ``coverage`` (the
reference's top measured by the scan) and the inliers' RMSE.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from insitu.geometry.pose import Pose4, apply, inverse, matrix, rot_z
from insitu.locate.flat_icp import Fit, icp_flat
from insitu.locate.reference import PartReference, coarse_features


@dataclass(frozen=True)
class Solution:
    """One pose of the part: world x, y, z (mm) of its frame's origin and its turn about z
    (degrees, −180 … 180); ``fitness``, ``coverage`` and ``rmse_mm`` as in the module's
    docstring; ``score`` = fitness × coverage; ``edges``: the edge samples that fixed x, y
    and the turn (0: not refined, the ICP's), ``sigma_mm`` and ``sigma_deg`` their 1σ
    (None: not refined; inf: the edges could not fix them, ``unheld`` then says why and
    ``free_xy`` is the world direction (2,) they left free),
    ``sigma_rim_mm`` the 1σ they leave at the part's rim (:mod:`insitu.locate.uncertainty`);
    ``image_edges``: the room-light frame's edge points that fixed x, y and the turn instead
    (0: not used, ``image_note`` says why when a frame was given), ``image_sigma_mm``,
    ``image_sigma_deg``, ``image_sigma_rim_mm`` their 1σ; ``image_conflict``: the frame's
    edges and the scan's put the part further apart than their σ allow."""

    x_mm: float
    y_mm: float
    z_mm: float
    angle_deg: float
    fitness: float
    coverage: float
    rmse_mm: float
    edges: int = 0
    sigma_mm: float | None = None
    sigma_deg: float | None = None
    unheld: str = ""
    free_xy: tuple[float, float] | None = None
    sigma_rim_mm: float | None = None
    image_edges: int = 0
    image_sigma_mm: float | None = None
    image_sigma_deg: float | None = None
    image_sigma_rim_mm: float | None = None
    image_note: str = ""
    image_conflict: bool = False

    @property
    def rim_sigma_mm(self) -> float:
        """1σ at the part's rim of the pose as given: the frame's when it placed the part,
        else the scan's edges' (inf: nothing measured it)."""
        s = self.image_sigma_rim_mm if self.image_edges else self.sigma_rim_mm
        return float("inf") if s is None else float(s)

    @property
    def turn_sigma_deg(self) -> float:
        """1σ of the turn as given, degrees (the frame's or the scan's edges'; inf: none)."""
        s = self.image_sigma_deg if self.image_edges else self.sigma_deg
        return float("inf") if s is None else float(s)

    @property
    def score(self) -> float:
        return self.fitness * self.coverage

    @property
    def T_world_part(self) -> np.ndarray:
        """(4, 4): part-frame points → world."""
        return matrix((np.radians(self.angle_deg), np.array([self.x_mm, self.y_mm, self.z_mm])))

    def describe(self) -> str:
        return (f"x {self.x_mm:.3f} y {self.y_mm:.3f} mm, {self.angle_deg:.2f}° (fitness "
                f"{self.fitness:.1%}, coverage {self.coverage:.1%})")


def subsample(points: np.ndarray, n: int) -> np.ndarray:
    if len(points) <= n:
        return points
    return points[np.random.default_rng(0).choice(len(points), n, replace=False)]


def global_fits(ref: PartReference, part: np.ndarray, s, z0: float,
            seeds: range = range(0), turns: bool = True) -> list[Fit]:
    """Coarse fits (world → part) from the turn search (with ``turns``) and from FPFH +
    RANSAC, a run for each of ``seeds`` (the scan's features computed only for them)."""
    import open3d as o3d

    v = s.voxel_mm
    rp, rn, rf = ref.coarse(v)
    rtree = ref.__dict__.setdefault("_coarse_tree", {}).setdefault(v, cKDTree(rp))
    if seeds:
        cp, _, cf = coarse_features(part, None, v)
    else:                                   # the same points, without normals and features
        cp = np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(
            np.ascontiguousarray(part))).voxel_down_sample(v).points)
    starts = _turn_search(rp, rtree, cp, ref.top_centroid, z0, s) if turns else []
    starts += [p for seed in seeds if (p := _fpfh_start(cp, cf, rp, rf, v, seed))]
    return [icp_flat(cp, rp, rn, rtree, p, (4 * v, 2 * v, v), iterations=10, inlier_mm=v)
            for p in starts]


def _turn_search(rp, rtree, cp, centre_r, z0: float, s) -> list[Pose4]:
    """Starts at the best-scoring turns (at least 20° apart): the scan's centroid on the
    reference's top centroid, z from the table."""
    angles = np.radians(np.arange(0.0, 360.0, s.turn_step_deg))
    cs = cp[:, :2].mean(axis=0)
    poses = []
    for a in angles:
        t = np.append(centre_r - rot_z(a)[:2, :2] @ cs, z0)
        poses.append((a, t))
    mapped = np.concatenate([apply(p, cp) for p in poses])
    dist, _ = rtree.query(mapped, distance_upper_bound=2 * s.voxel_mm)
    score = np.isfinite(dist).reshape(len(angles), -1).mean(axis=1)
    chosen: list[int] = []
    for i in np.argsort(-score):
        gap = [abs((np.degrees(angles[i] - angles[j]) + 180) % 360 - 180) for j in chosen]
        if all(g >= 20 for g in gap):
            chosen.append(int(i))
        if len(chosen) == s.turn_candidates:
            break
    return [poses[i] for i in chosen]


def _fpfh_start(cp, cf, rp, rf, v: float, seed: int = 0) -> Pose4 | None:
    """FPFH + RANSAC (Open3D, seeded with ``seed``) start, flattened to a turn about z; None
    when it tilts the part more than 10°."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src, dst = (o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(p)))
                for p in (cp, rp))
    fs, fd = reg.Feature(), reg.Feature()
    fs.data, fd.data = np.ascontiguousarray(cf), np.ascontiguousarray(rf)
    o3d.utility.random.seed(seed)
    res = reg.registration_ransac_based_on_feature_matching(
        src, dst, fs, fd, False, 1.5 * v, reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
         reg.CorrespondenceCheckerBasedOnDistance(1.5 * v)],
        reg.RANSACConvergenceCriteria(50_000, 0.999))
    T = np.asarray(res.transformation)
    if res.fitness == 0 or T[2, 2] < np.cos(np.radians(10)):
        return None
    return float(np.arctan2(T[1, 0], T[0, 0])), T[:3, 3].copy()


def refine(ref: PartReference, fine: np.ndarray, fits: list[Fit],
            s) -> list[Solution]:
    """Fine ICP of each distinct coarse fit; the distinct solutions, best first."""
    scan_tree = cKDTree(fine)
    sols: list[Solution] = []
    for f in sorted(fits, key=lambda f: -f.fitness):
        if any(not distinct(f.pose, pose_of(o)) for o in sols):
            continue
        fit = icp_flat(fine, ref.points, ref.normals, ref.tree, f.pose, (1.0, 0.5, s.inlier_mm),
                       iterations=15, inlier_mm=s.inlier_mm)
        sol = solution_of(fit, ref, scan_tree, s.cover_mm)
        if all(distinct(fit.pose, pose_of(o)) for o in sols):
            sols.append(sol)
    return sorted(sols, key=lambda o: -o.score)


def pose_of(sol: Solution) -> Pose4:
    """World → part pose of ``sol``."""
    return inverse((np.radians(sol.angle_deg), np.array([sol.x_mm, sol.y_mm, sol.z_mm])))


_PROBE = np.array([[x, y, 0.0] for x in (-20, 0, 20) for y in (-20, 0, 20)])


def distinct(a: Pose4, b: Pose4, tol_mm: float = 1.0) -> bool:
    """Whether two world → part poses move points 20 mm around the origin apart by more
    than ``tol_mm``."""
    return bool(np.max(np.linalg.norm(apply(a, _PROBE) - apply(b, _PROBE), axis=1)) > tol_mm)


def solution_of(fit: Fit, ref: PartReference, scan_tree: cKDTree, cover_mm: float) -> Solution:
    a, t = inverse(fit.pose)
    top = apply((a, t), ref.top)
    dist, _ = scan_tree.query(top, distance_upper_bound=cover_mm)
    cover = float(np.isfinite(dist).mean()) if len(top) else 0.0
    ang = (np.degrees(a) + 180.0) % 360.0 - 180.0
    return Solution(float(t[0]), float(t[1]), float(t[2]), float(ang), fit.fitness, cover,
                    fit.rmse_mm)


def joined_turn(ref: PartReference, sol: Solution, other_deg: float,
                other_sigma: float | None) -> Solution:
    """``sol`` with its turn joined by inverse variances to ``other_deg`` (1σ
    ``other_sigma``), an independent measure of the same turn (the scan's edges and the
    room-light frame's: independent against a mesh ``ref``, not against a scan reference
    whose outline both share), turned about the top's centre (where ``sol`` put it stays);
    ``sol`` unchanged when either turn is not measured or the two lie further apart than 2σ
    of the two together (one of them biased). The σ at the rim stays ``sol``'s."""
    a, b = sol.turn_sigma_deg, other_sigma
    if ref.kind != "mesh" or b is None or not (np.isfinite(a) and np.isfinite(b) and a > 0
                                                and b > 0):
        return sol
    d = (other_deg - sol.angle_deg + 180.0) % 360.0 - 180.0
    if abs(d) > 2 * np.hypot(a, b):
        return sol
    angle = sol.angle_deg + d * a ** 2 / (a ** 2 + b ** 2)
    R0, R1 = rot_z(np.radians(sol.angle_deg))[:2, :2], rot_z(np.radians(angle))[:2, :2]
    xy = np.array([sol.x_mm, sol.y_mm]) + (R0 - R1) @ ref.top_centroid
    joined = float(a * b / np.hypot(a, b))
    return replace(sol, x_mm=float(xy[0]), y_mm=float(xy[1]),
                   angle_deg=float((angle + 180.0) % 360.0 - 180.0),
                   **{"image_sigma_deg" if sol.image_edges else "sigma_deg": joined})
