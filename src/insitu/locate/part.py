"""Locate a part lying flat on the table in a scan: its pose ``T_world_part`` (a turn about z
and a shift), or a refusal naming why — never a doubtful pose.

1. The table is taken away (:func:`~insitu.locate.reference.find_table`).
2. Global step (:mod:`insitu.locate.search`): a search over turns, and FPFH + RANSAC
   starts (:data:`RANSAC_RUNS` runs) where its best would be refused, each refined by a
   flat ICP; the distinct solutions scored by ``fitness``, ``coverage`` and the inliers'
   RMSE.
3. x, y and the turn from the edges the scan lines cross (:mod:`insitu.locate.edge_align`).
4. The best is refused when it fits poorly, is only partly in the scan, or a second distinct
   solution scores within ``ambiguity`` of it unless ``prefer_angle`` picks one of them
   (:func:`insitu.locate.refusal.choose`).
5. With a room-light frame of the camera the scan was measured through, x, y and the turn
   are taken from the top's edges in it (:mod:`insitu.locate.image_edges`) when they hold
   the pose better than the scan's edges and agree with them (3σ and ``agree_mm``;
   ``UNHELD_MM`` where the scan's edges do not hold it; against a mesh the two turns joined:
   :func:`~insitu.locate.search.joined_turn`); a frame that disagrees refuses the pose.
6. The pose is given only when its σ (:mod:`insitu.locate.uncertainty`: segments of each
   edge, a bias and a tilt per edge, the reference's own outline) puts it within the
   tolerance: :data:`SIGMAS` σ at the part's rim within ``tolerance_mm``, 3σ of the turn
   within ``turn_bound_deg`` (and, when set, :data:`SIGMAS` σ of the turn within
   ``turn_tolerance_deg``); else refused, saying what would pin it down (a crossed pass,
   the room-light frame, a CAD reference, finer lines: :func:`insitu.locate.refusal.pinned`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from insitu.geometry.camera import CameraModel
from insitu.geometry.pose import apply, matrix, rot_z
from insitu.locate.edge_align import align_edges, edge_samples
from insitu.locate.flat_icp import score
from insitu.locate.image_edges import SEARCH_PX, align_image, frame_of
from insitu.locate.reference import PartReference, above_table, find_table, thin
from insitu.locate.refusal import SIGMAS, LocateRefused, choose, margin, pinned
from insitu.locate.search import (
    Solution,
    distinct,
    global_fits,
    joined_turn,
    pose_of,
    refine,
    solution_of,
    subsample,
)
from insitu.locate.uncertainty import rim_moved, rim_sigma
from insitu.locate.unheld import pin_advice, unheld_reason

MIN_POINTS = 200
UNHELD_MM = 1.0
CONSISTENT = 2.0
"""The scan's and the frame's poses further apart at the part's rim than this many σ of the
two together: one of them carries a bias its σ does not count (another renderer's room light
moved the arc's edges 0.055 mm, 4σ of the frame's own), and the pose given takes half that
distance as its 1σ at the rim."""
WIDE = 3
"""How far the room-light frame's edges may move a pose the scan's edges did not hold (the
ICP's along the direction they left free: a few tenths of a mm, 0.64 at a step block lying
along the lines); they are first looked for ``WIDE`` times further out."""
NEAR_MM = 0.01
"""The wide search stops once a step moves the part less than this: a start for the
narrower search, which then settles it to 0.001 mm."""
MAX_FINE_POINTS = 40_000
RANSAC_RUNS = 4
"""FPFH + RANSAC starts, each seeded anew, when the turn search's best would be refused (too
few of the scan's points fit, or too little of the top is covered: the independent
recording's half block, whose centroid the turn search cannot use): Open3D's RANSAC is not
repeatable whatever its seed, and one run finds that block 17 times in 20. A run takes
0.25–0.35 s of a produce part's 1.5 s locate (one core); where the turn search finds the
part, none is made."""
__all__ = ["SIGMAS", "LocateRefused", "LocateSettings", "PartPose", "locate_part"]


@dataclass(frozen=True)
class LocateSettings:
    """Thresholds and grids of :func:`locate_part` (mm, degrees, fractions 0 … 1).
    ``table_z_mm``: the table's height when known (None: found in the scan);
    ``tolerance_mm``: a pose is given only when :data:`SIGMAS` × its 1σ at the part's rim
    lies within it (the marking tolerance) and 3σ of its turn within ``turn_bound_deg`` (no
    pose given 0.1° off, however small the part); ``turn_tolerance_deg``: when set, also
    :data:`SIGMAS` σ of the turn within it (the marks' own angle tolerance; None: none, the
    rim holds the marks' places: an insert's turn floor, 1σ 0.026–0.029° with two of its
    sides seen, moves its rim 9.09 mm out 0.0044 mm)."""

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
    tolerance_mm: float = 0.05
    turn_bound_deg: float = 0.1
    turn_tolerance_deg: float | None = None
    turn_step_deg: float = 5.0
    turn_candidates: int = 6
    agree_mm: float = 0.05   # + 3σ: how far the frame's pose may lie from the scan's (whose
    #                          σ misses its pixel aliasing: the arc at 91°, 0.053 mm at its rim)


@dataclass(frozen=True)
class PartPose:
    """Where the part lies: ``best`` solution, the ``second`` best distinct one (None: none
    found), the table's height (None: no table in the scan), the part's points used, the
    time taken, s, and the ``tolerance`` (mm at the rim, degrees) its 1σ was held to."""

    best: Solution
    second: Solution | None
    table_z_mm: float | None
    points: int
    seconds: float
    tolerance: tuple[float, float] | None = None
    turn_tolerance_deg: float | None = None

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
                "sigma_rim_mm": finite(b.rim_sigma_mm),
                "tolerance_mm": (self.tolerance or (None, None))[0],
                "turn_bound_deg": (self.tolerance or (None, None))[1],
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
    fine = subsample(thin(part, s.fine_voxel_mm), MAX_FINE_POINTS)
    z0 = reference.base_z_mm - (table if table is not None else part[:, 2].min())
    fits = global_fits(reference, part, s, z0)
    sols = refine(reference, fine, fits, s)
    if not sols or sols[0].fitness < s.min_fitness or sols[0].coverage < s.min_coverage:
        fits += global_fits(reference, part, s, z0, range(RANSAC_RUNS), turns=False)
        sols = refine(reference, fine, fits, s)
    sols = _aligned(reference, pts, None if lines is None else np.asarray(lines), ~up, fine,
                    sols, s, camera)
    framed = (None if image is None or camera is None else
              lambda best: _imaged(reference, best, image, camera, s))
    best, second = choose(sols, len(part), where, s, prefer_angle, framed)
    pinned(best, s, lambda: pin_advice(reference.kind, lines, pts, image is not None))
    return PartPose(best, second, table, len(part), time.perf_counter() - t0,
                    (s.tolerance_mm, s.turn_bound_deg), s.turn_tolerance_deg)


def _imaged(ref: PartReference, best: Solution, image: np.ndarray, camera: CameraModel,
            s: LocateSettings) -> Solution:
    """``best`` with x, y and the turn from the room-light frame's edges when they agree with
    the scan's (within 3σ of the two together and ``agree_mm``; where the scan's edges left
    a direction free, along it by up to ``UNHELD_MM``) and hold the pose better; else why
    not (``image_note``; ``image_conflict``: the two disagree where the scan held it)."""
    scan = best.rim_sigma_mm
    start = best.T_world_part
    frame = frame_of(image) if image.shape[:2] == (camera.height, camera.width) else image
    if not SIGMAS * scan <= s.tolerance_mm:     # the scan's pose may lie tenths of a mm off
        wide = align_image(frame, camera, ref.heights, ref.outline, start,
                           search_px=WIDE * SEARCH_PX, reference_mm=ref.outline_sigma_mm,
                           near_mm=NEAR_MM)
        start = start if isinstance(wide, str) else matrix(
            (wide.angle_rad, np.array([*wide.xy_mm, best.z_mm])))
    fit = align_image(frame, camera, ref.heights, ref.outline, start,
                      reference_mm=ref.outline_sigma_mm)
    if isinstance(fit, str):
        return replace(best, image_note=f"not used: {fit}")
    sigma = rim_sigma(fit.cov, ref.rim @ rot_z(fit.angle_rad)[:2, :2].T)
    angle = (np.degrees(fit.angle_rad) + 180.0) % 360.0 - 180.0
    if not sigma < scan:
        return joined_turn(ref, replace(best, image_note=f"not used: its edges hold the pose "
                           f"to {sigma:.3f} mm (1σ) at the part's rim, the scan's to {scan:.3f}"),
                           angle, fit.sigma_deg)
    framed = replace(best, x_mm=float(fit.xy_mm[0]), y_mm=float(fit.xy_mm[1]),
                     angle_deg=float(angle), image_edges=fit.edges,
                     image_sigma_mm=fit.sigma_mm, image_sigma_deg=fit.sigma_deg,
                     image_sigma_rim_mm=sigma, image_note=fit.note)
    held = best.T_world_part
    if not np.isfinite(scan) and best.free_xy is not None:   # may slide along the free way
        free = np.asarray(best.free_xy)
        slide = float((fit.xy_mm - held[:2, 3]) @ free)
        held = held.copy()
        held[:2, 3] += min(abs(slide), UNHELD_MM) * np.sign(slide) * free
    moved = rim_moved(ref.rim, held, framed.T_world_part)
    allowed = s.agree_mm + 3 * float(np.hypot(scan, sigma) if np.isfinite(scan) else sigma)
    if moved > allowed:
        return replace(best, image_conflict=bool(np.isfinite(scan)), image_note=(
            f"{'' if np.isfinite(scan) else 'not used: '}its edges put the part {moved:.3f} mm "
            f"(at the rim) from the scan's pose, more than the {allowed:.3f} mm the two may "
            "differ"))
    together = float(np.hypot(scan, sigma))
    if np.isfinite(scan) and moved > CONSISTENT * together:   # one of the two is biased
        floor, note = moved / 2, (f"its edges and the scan's put the part {moved:.3f} mm apart "
                                  f"at the rim, beyond {CONSISTENT:g}σ of the two together "
                                  f"({together:.3f} mm): either may be the biased one, 1σ at "
                                  f"the rim taken as {moved / 2:.3f} mm")
        best = replace(best, sigma_rim_mm=max(scan, floor), image_note=note)
        framed = replace(framed, image_sigma_rim_mm=max(sigma, floor), image_note=note)
    if not margin(framed, s) < margin(best, s):
        return joined_turn(ref, best if best.image_note else replace(best, image_note=(
            f"not used: its edges hold the pose to {sigma:.3f} mm at the part's rim and "
            f"{fit.sigma_deg:.3f}° (1σ), the scan's to {scan:.3f} mm and {best.sigma_deg:.3f}°")),
            angle, fit.sigma_deg)
    return joined_turn(ref, framed, best.angle_deg, best.sigma_deg)


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
        a, t = pose_of(sol)
        ep, up = apply((a, t), found.points), found.dirs @ rot_z(a)[:2, :2].T
        step = align_edges(ref.heights, ep, up, reference_mm=ref.outline_sigma_mm)
        edges, why, free_xy = (0, np.inf, np.inf, np.inf), "", None
        if step is None:
            why, free = unheld_reason(ref.heights, ep, up, a)
            step = None if free is None else align_edges(ref.heights, ep, up, free=free,
                                                         reference_mm=ref.outline_sigma_mm)
            free_xy = None if free is None else tuple(rot_z(-a)[:2, :2] @ free)
            if step is not None:              # the turn and the shift across held: refined
                edges = (step.samples, np.inf, step.sigma_deg, np.inf)
        else:
            edges = (step.samples, step.sigma_mm, step.sigma_deg,
                     rim_sigma(step.cov, ref.rim - step.centre_mm))
        if step is not None:
            a = a + step.angle_rad
            t = rot_z(step.angle_rad) @ t + np.append(step.shift_mm, 0.0)
        fit = score((a, t), fine, ref.points, ref.normals, ref.tree, s.inlier_mm)
        out.append(replace(solution_of(fit, ref, scan_tree, s.cover_mm), edges=edges[0],
                           sigma_mm=edges[1], sigma_deg=edges[2], sigma_rim_mm=edges[3],
                           unheld=why, free_xy=free_xy))
    kept: list[Solution] = []                 # two starts may have met on the same edges
    for sol in sorted(out, key=lambda o: -o.score):
        if all(distinct(pose_of(sol), pose_of(k)) for k in kept):
            kept.append(sol)
    return kept
