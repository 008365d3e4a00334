"""Locate a part lying flat on the table in a scan: its pose ``T_world_part`` (a turn about z
and a shift), or a refusal naming why — never a doubtful pose.

1. The table is taken away (:func:`~insitu.locate.reference.find_table`).
2. Global step, two ways, on a ``voxel_mm`` grid: FPFH features matched by RANSAC
   (``open3d.pipelines.registration``; up to :data:`RANSAC_RUNS` times), and a search over
   turns about z (every ``turn_step_deg``, x, y from the tops' centroids) for parts with few
   features; each start refined by a coarse flat ICP.
3. Fine step: point-to-plane ICP of the scan (thinned to ``fine_voxel_mm``, table excluded)
   onto the dense reference, restricted to the 4 degrees of freedom of a part lying flat
   (:mod:`insitu.locate.flat_icp`); then x, y and the turn from the edges the scan lines
   cross (:mod:`insitu.locate.edge_align`), which flat tops do not give the ICP.
4. Each distinct solution is scored: ``fitness`` (the scan's points within ``inlier_mm`` of
   the reference's surface), ``coverage`` (the reference's top measured by the scan) and the
   inliers' RMSE. The best is refused when it fits poorly or is only partly in the scan;
   when a second distinct solution scores within ``ambiguity`` of it (a symmetric part)
   unless ``prefer_angle`` picks exactly one of them; and when the edges leave the pose
   uncertain by more than ``max_sigma_mm`` (1σ, at the part's rim).
5. With a room-light frame of the camera the scan was measured through, the chosen pose's
   x, y and turn are taken from the top's edges in it (:mod:`insitu.locate.image_edges`),
   seen whole there, when they hold the pose to ``max_sigma_mm`` and agree with the scan's
   within its own uncertainty (3σ + ``agree_mm``; 0.3 mm where the scan's edges did not
   hold it); then the uncertainty check of 4. is the frame's. Else the scan's pose stands,
   the reason noted.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from insitu.errors import MeasurementError
from insitu.geometry.camera import CameraModel
from insitu.geometry.pose import Pose4, apply, inverse, matrix, rot_z
from insitu.locate.flat_icp import Fit, icp_flat, score
from insitu.locate.edge_align import (align_edges, direction_name, edge_samples,
                                       unheld_reason)
from insitu.locate.image_edges import align_image
from insitu.locate.reference import (PartReference, above_table, coarse_features,
                                           find_table, thin)

MIN_POINTS = 200
UNHELD_MM = 0.3
"""How far the room-light frame's edges may move a pose the scan's edges did not hold."""
MAX_FINE_POINTS = 40_000
RANSAC_RUNS = 4
"""FPFH + RANSAC starts, each seeded anew, when the first run's best would be refused: Open3D's
RANSAC is not repeatable whatever its seed, and one run finds the independent recording's half
block (whose centroid the turn search cannot use) 17 times in 20 (0.3 s a run at 200 k
points, one core: a run, not four, where the part is found)."""


class LocateRefused(MeasurementError):
    """The part's pose is not given: ``reason`` is "no-part", "poor-fit", "partial",
    "ambiguous" or "not-preferred"; the message names the numbers; ``best``: the pose that
    was refused as not pinned down (None otherwise), for scoring."""

    def __init__(self, reason: str, message: str, best: Solution | None = None):
        super().__init__(message)
        self.reason = reason
        self.best = best


@dataclass(frozen=True)
class LocateSettings:
    """Thresholds and grids of :func:`locate_part` (mm, degrees, fractions 0 … 1).
    ``table_z_mm``: the table's height when known (None: found in the scan)."""

    table_band_mm: float = 0.5
    table_z_mm: float | None = None
    voxel_mm: float = 1.0
    fine_voxel_mm: float = 0.3
    inlier_mm: float = 0.3
    cover_mm: float = 1.0
    min_fitness: float = 0.85
    min_coverage: float = 0.8
    max_rmse_mm: float = 0.12
    ambiguity: float = 0.05
    max_sigma_mm: float = 0.03
    turn_step_deg: float = 5.0
    turn_candidates: int = 6
    agree_mm: float = 0.05   # + 3σ: how far the frame's pose may lie from the scan's (whose
    #                          σ misses its pixel aliasing: the arc at 91°, 0.053 mm at its rim)


@dataclass(frozen=True)
class Solution:
    """One pose of the part: world x, y, z (mm) of its frame's origin and its turn about z
    (degrees, −180 … 180); ``fitness``, ``coverage`` and ``rmse_mm`` as in the module's
    docstring; ``score`` = fitness × coverage; ``edges``: the edge samples that fixed x, y
    and the turn (0: not refined, the ICP's), ``sigma_mm`` and ``sigma_deg`` their 1σ
    (None: not refined; inf: the edges could not fix them, ``unheld`` then says why);
    ``image_edges``: the room-light frame's edge points that fixed x, y and the turn instead
    (0: not used, ``image_note`` says why when a frame was given), ``image_sigma_mm``,
    ``image_sigma_deg`` their 1σ."""

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
    image_edges: int = 0
    image_sigma_mm: float | None = None
    image_sigma_deg: float | None = None
    image_note: str = ""

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


@dataclass(frozen=True)
class PartPose:
    """Where the part lies: ``best`` solution, the ``second`` best distinct one (None: none
    found), the table's height (None: no table in the scan), the part's points used and the
    time taken, s."""

    best: Solution
    second: Solution | None
    table_z_mm: float | None
    points: int
    seconds: float

    @property
    def T_world_part(self) -> np.ndarray:
        """(4, 4) float64: maps part-frame points (mm) to world points (mm)."""
        return self.best.T_world_part

    def to_dict(self) -> dict:
        """The numbers of POSE.json (without its envelope)."""
        b, s = self.best, self.second
        finite = lambda v: v if v is not None and np.isfinite(v) else None   # noqa: E731
        return {"T_world_part": self.T_world_part.tolist(), "x_mm": b.x_mm, "y_mm": b.y_mm,
                "z_mm": b.z_mm, "angle_deg": b.angle_deg, "fitness": b.fitness,
                "coverage": b.coverage, "inlier_rmse_mm": b.rmse_mm, "edge_samples": b.edges,
                "sigma_mm": finite(b.sigma_mm), "sigma_deg": finite(b.sigma_deg),
                "image_edges": b.image_edges, "image_sigma_mm": b.image_sigma_mm,
                "image_sigma_deg": b.image_sigma_deg, "image_note": b.image_note,
                "second": None if s is None else {
                    k: getattr(s, k) for k in ("x_mm", "y_mm", "z_mm", "angle_deg", "fitness",
                                               "coverage", "rmse_mm")} | {"score": s.score},
                "table_z_mm": self.table_z_mm, "points": self.points,
                "seconds": self.seconds}


def locate_part(reference: PartReference, points: np.ndarray,
                settings: LocateSettings = LocateSettings(),
                prefer_angle: tuple[float, float] | None = None,
                lines: np.ndarray | None = None,
                camera: CameraModel | None = None,
                image: np.ndarray | None = None) -> PartPose:
    """The pose of ``reference``'s part in a scan ``points`` (N, 3) float64, mm, world
    frame (table included or not); ``lines`` (N,) int: each point's scan line (the cloud's
    ``line`` attribute), for the edge step — without it x, y and the turn are the ICP's,
    a few tenths of a mm off on flat parts; ``camera``: the camera the scan was measured
    through (the height calibration's), so the edge step takes each line's points in the
    order of their pixels (:mod:`insitu.locate.edge_align`) — without it, in the order
    along the line in x, y, and edges crossed obliquely are found short. ``prefer_angle``
    (lo, hi) degrees: of solutions that fit
    nearly equally well (a symmetric part), take the one turned within lo … hi (wrapping
    around 360°). ``image`` (H, W): a frame of ``camera`` under the room light, laser off,
    the part as scanned — its edges then give x, y and the turn (step 5 of the module's
    docstring). Raises :class:`LocateRefused` (a MeasurementError) naming why when the
    part is not found, fits poorly, is only partly in the scan or is ambiguous."""
    t0 = time.perf_counter()
    s = settings
    pts = np.asarray(points, np.float64)
    table = s.table_z_mm if s.table_z_mm is not None else find_table(pts, s.table_band_mm)
    up = above_table(pts, table, s.table_band_mm)
    part = pts[up]
    where = "no table found" if table is None else f"the table at z = {table:.2f} mm"
    if len(part) < MIN_POINTS:
        raise LocateRefused("no-part", f"no part in the scan: {len(part)} points above "
                                       f"{where} (at least {MIN_POINTS} needed)")
    fine = _subsample(thin(part, s.fine_voxel_mm), MAX_FINE_POINTS)
    z0 = reference.base_z_mm - (table if table is not None else part[:, 2].min())
    fits = _global(reference, part, s, z0)
    sols = _refine(reference, fine, fits, s)
    if not sols or sols[0].fitness < s.min_fitness or sols[0].coverage < s.min_coverage:
        fits += _global(reference, part, s, z0, range(1, RANSAC_RUNS), turns=False)
        sols = _refine(reference, fine, fits, s)
    sols = _aligned(reference, pts, None if lines is None else np.asarray(lines), ~up, fine,
                    sols, s, camera)
    rim = float(np.linalg.norm(reference.top[:, :2] - reference.top_centroid, axis=1).max())
    framed = (None if image is None or camera is None else
              lambda best: _imaged(reference, best, image, camera, s, rim))
    best, second = _choose(sols, len(part), where, s, prefer_angle, rim, framed)
    return PartPose(best, second, table, len(part), time.perf_counter() - t0)


def _imaged(ref: PartReference, best: Solution, image: np.ndarray, camera: CameraModel,
            s: LocateSettings, rim: float) -> Solution:
    """``best`` with x, y and the turn from the room-light frame's edges when they hold the
    pose to ``max_sigma_mm`` at the rim and agree with the scan's; else ``best`` with why
    not (``image_note``)."""
    fit = align_image(image, camera, ref.heights, ref.outline, best.T_world_part)
    if isinstance(fit, str):
        return replace(best, image_note=f"not used: {fit}")
    spread = float(np.hypot(fit.sigma_mm, np.radians(fit.sigma_deg) * rim))
    if spread > s.max_sigma_mm:
        return replace(best, image_note=f"not used: its edges hold the pose to {spread:.3f} "
                                        f"mm at the part's rim (at most {s.max_sigma_mm:g})")
    angle = (np.degrees(fit.angle_rad) + 180.0) % 360.0 - 180.0
    turn = np.radians((angle - best.angle_deg + 180.0) % 360.0 - 180.0)
    moved = float(np.hypot(np.hypot(fit.xy_mm[0] - best.x_mm, fit.xy_mm[1] - best.y_mm),
                           turn * rim))
    held = best.sigma_mm is not None and np.isfinite(best.sigma_mm)
    allowed = s.agree_mm + (3 * float(np.hypot(best.sigma_mm, np.radians(best.sigma_deg) * rim))
                            if held else UNHELD_MM)
    if moved > allowed:
        return replace(best, image_note=(
            f"not used: its edges put the part {moved:.3f} mm (at the rim) from the scan's "
            f"pose, more than the {allowed:.3f} mm the two may differ"))
    return replace(best, x_mm=float(fit.xy_mm[0]), y_mm=float(fit.xy_mm[1]),
                   angle_deg=float(angle), image_edges=fit.edges,
                   image_sigma_mm=fit.sigma_mm, image_sigma_deg=fit.sigma_deg)


def _subsample(points: np.ndarray, n: int) -> np.ndarray:
    if len(points) <= n:
        return points
    return points[np.random.default_rng(0).choice(len(points), n, replace=False)]


def _global(ref: PartReference, part: np.ndarray, s: LocateSettings, z0: float,
            seeds: range = range(1), turns: bool = True) -> list[Fit]:
    """Coarse fits (world → part) from the turn search (with ``turns``) and from FPFH +
    RANSAC, a run for each of ``seeds``."""
    v = s.voxel_mm
    rp, rn, rf = ref.coarse(v)
    rtree = ref.__dict__.setdefault("_coarse_tree", {}).setdefault(v, cKDTree(rp))
    cp, _, cf = coarse_features(part, None, v)
    starts = _turn_search(rp, rtree, cp, ref.top_centroid, z0, s) if turns else []
    starts += [p for seed in seeds if (p := _fpfh_start(cp, cf, rp, rf, v, seed))]
    return [icp_flat(cp, rp, rn, rtree, p, (4 * v, 2 * v, v), iterations=10, inlier_mm=v)
            for p in starts]


def _turn_search(rp, rtree, cp, centre_r, z0: float, s: LocateSettings) -> list[Pose4]:
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


def _refine(ref: PartReference, fine: np.ndarray, fits: list[Fit],
            s: LocateSettings) -> list[Solution]:
    """Fine ICP of each distinct coarse fit; the distinct solutions, best first."""
    scan_tree = cKDTree(fine)
    sols: list[Solution] = []
    for f in sorted(fits, key=lambda f: -f.fitness):
        if any(not _distinct(f.pose, _pose_of(o)) for o in sols):
            continue
        fit = icp_flat(fine, ref.points, ref.normals, ref.tree, f.pose, (1.0, 0.5, s.inlier_mm),
                       iterations=15, inlier_mm=s.inlier_mm)
        sol = _solution(fit, ref, scan_tree, s.cover_mm)
        if all(_distinct(fit.pose, _pose_of(o)) for o in sols):
            sols.append(sol)
    return sorted(sols, key=lambda o: -o.score)


def _aligned(ref: PartReference, pts: np.ndarray, lines: np.ndarray | None,
             table: np.ndarray, fine: np.ndarray, sols: list[Solution],
             s: LocateSettings, camera: CameraModel | None) -> list[Solution]:
    """The solutions within reach of the best (those that may be chosen) with x, y and the
    turn refined on the edges the scan lines cross (:mod:`insitu.locate.edge_align`), z
    kept; unchanged without line indices or too few edge samples."""
    if not sols or lines is None:
        return sols
    scan_tree = cKDTree(fine)
    found = edge_samples(pts, lines, table, camera)
    out = []
    for sol in sols:
        if sol.score < sols[0].score - 2 * s.ambiguity:
            out.append(sol)
            continue
        a, t = _pose_of(sol)
        ep, up = apply((a, t), found.points), found.dirs @ rot_z(a)[:2, :2].T
        step = align_edges(ref.heights, ep, up)
        edges, why = (0, np.inf, np.inf), ""
        if step is None:
            why, free = unheld_reason(ref.heights, ep, up, a)
            step = None if free is None else align_edges(ref.heights, ep, up, free=free)
            if step is not None:              # the turn and the shift across held: refined
                edges = (step.samples, np.inf, step.sigma_deg)
        else:
            edges = (step.samples, step.sigma_mm, step.sigma_deg)
        if step is not None:
            a = a + step.angle_rad
            t = rot_z(step.angle_rad) @ t + np.append(step.shift_mm, 0.0)
        fit = score((a, t), fine, ref.points, ref.normals, ref.tree, s.inlier_mm)
        out.append(replace(_solution(fit, ref, scan_tree, s.cover_mm), edges=edges[0],
                           sigma_mm=edges[1], sigma_deg=edges[2], unheld=why))
    kept: list[Solution] = []                 # two starts may have met on the same edges
    for sol in sorted(out, key=lambda o: -o.score):
        if all(_distinct(_pose_of(sol), _pose_of(k)) for k in kept):
            kept.append(sol)
    return kept


def _slid(a: Solution, b: Solution) -> str | None:
    """How two poses that fit alike differ by a shift alone (turned less than 2° apart):
    the direction nothing holds, or None when they are turned apart (a symmetric part)."""
    if abs((a.angle_deg - b.angle_deg + 180.0) % 360.0 - 180.0) >= 2.0:
        return None
    d = np.array([b.x_mm - a.x_mm, b.y_mm - a.y_mm])
    name, _ = direction_name(d / max(float(np.linalg.norm(d)), 1e-12))
    return (f"{a.describe()} and {b.describe()} fit nearly equally, "
            f"{float(np.linalg.norm(d)):.2f} mm apart along {name}: nothing holds the part "
            f"along {name}" + ("" if a.sigma_mm is not None else
                               " (the cloud records no scan lines: no edge step)"))


def _pose_of(sol: Solution) -> Pose4:
    """World → part pose of ``sol``."""
    return inverse((np.radians(sol.angle_deg), np.array([sol.x_mm, sol.y_mm, sol.z_mm])))


_PROBE = np.array([[x, y, 0.0] for x in (-20, 0, 20) for y in (-20, 0, 20)])


def _distinct(a: Pose4, b: Pose4, tol_mm: float = 1.0) -> bool:
    """Whether two world → part poses move points 20 mm around the origin apart by more
    than ``tol_mm``."""
    return bool(np.max(np.linalg.norm(apply(a, _PROBE) - apply(b, _PROBE), axis=1)) > tol_mm)


def _solution(fit: Fit, ref: PartReference, scan_tree: cKDTree, cover_mm: float) -> Solution:
    a, t = inverse(fit.pose)
    top = apply((a, t), ref.top)
    dist, _ = scan_tree.query(top, distance_upper_bound=cover_mm)
    cover = float(np.isfinite(dist).mean()) if len(top) else 0.0
    ang = (np.degrees(a) + 180.0) % 360.0 - 180.0
    return Solution(float(t[0]), float(t[1]), float(t[2]), float(ang), fit.fitness, cover,
                    fit.rmse_mm)


def _in_range(angle: float, lo: float, hi: float) -> bool:
    return (angle - lo) % 360.0 <= (hi - lo) % 360.0 or (hi - lo) >= 360.0


def _choose(sols: list[Solution], n: int, where: str, s: LocateSettings,
            prefer: tuple[float, float] | None, radius_mm: float, framed=None
            ) -> tuple[Solution, Solution | None]:
    """(best, second) or LocateRefused. ``framed``: the best refined by the room-light
    frame's edges (:func:`_imaged`; None: no frame) — which also place a part whose scan
    edges left it too uncertain, when they agree with its pose."""
    top = sols[0] if sols else None
    if top is None or top.fitness < s.min_fitness * 0.6 or top.coverage < s.min_coverage / 2:
        fit, cover = (top.fitness, top.coverage) if top else (0.0, 0.0)
        raise LocateRefused("no-part", f"part not found: at best the reference fits "
                                       f"{fit:.0%} of the {n:,} points above {where} and "
                                       f"covers {cover:.0%} of its top")
    if top.coverage < s.min_coverage:
        raise LocateRefused("partial", f"only partly in the scan: {top.coverage:.0%} of the "
                            f"reference's top measured (at least {s.min_coverage:.0%} needed) "
                            f"at {top.describe()}")
    near = [o for o in sols if o.score >= top.score - s.ambiguity]
    if prefer is not None:
        pick = [o for o in near if _in_range(o.angle_deg, *prefer)]
        if not pick:
            raise LocateRefused("not-preferred", "no well-fitting pose turned within "
                                f"{prefer[0]:g} … {prefer[1]:g}°: found "
                                + "; ".join(o.describe() for o in near))
        near = pick
    if len(near) > 1 and (slid := _slid(near[0], near[1])) is not None:
        raise LocateRefused("poor-fit", f"x, y and the turn are not pinned down: {slid}",
                            near[0])
    if len(near) > 1:
        raise LocateRefused("ambiguous", f"ambiguous: {near[0].describe()} and "
                            f"{near[1].describe()} fit nearly equally (a symmetric part?): "
                            "say which with a preferred angle range LO HI")
    best = near[0]
    second = next((o for o in sols if o is not best), None)
    if best.fitness < s.min_fitness or best.rmse_mm > s.max_rmse_mm:
        raise LocateRefused("poor-fit", f"fits poorly: {best.describe()}, inlier RMSE "
                            f"{best.rmse_mm:.3f} mm (needed: fitness ≥ {s.min_fitness:.0%}, "
                            f"RMSE ≤ {s.max_rmse_mm:g} mm)")
    if framed is not None:
        best = framed(best)
    if best.sigma_mm is not None and not best.image_edges:
        frame = f"; the room-light frame: {best.image_note}" if best.image_note else ""
        spread = float(np.hypot(best.sigma_mm, np.radians(best.sigma_deg) * radius_mm))
        if not np.isfinite(spread):
            raise LocateRefused("poor-fit", f"x, y and the turn are not pinned down at "
                                f"{best.describe()}: {best.unheld}{frame}", best)
        if not spread <= s.max_sigma_mm:
            raise LocateRefused(
                "poor-fit", f"x, y and the turn are not pinned down by the edges the scan lines "
                f"cross ({best.edges} samples; 1σ {best.sigma_mm:.3f} mm and "
                f"{best.sigma_deg:.3f}°, {spread:.3f} mm at the part's rim, at most "
                f"{s.max_sigma_mm:g} mm): scan finer (binning, spacing), or turn the part or "
                f"the scan when its edges run along the lines{frame}", best)
    return best, second
