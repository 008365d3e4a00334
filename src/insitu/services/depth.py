"""Pockets measured on a recorded scan (``insitu depth``): the recording replayed as a depth
scan replays it (centres across the line only, :data:`~insitu.services.pocket.DEPTH_CENTRES`),
or a measured cloud that keeps each point's line; each pocket's depth from its floor against
the top of the same lines (:func:`~insitu.marking.engrave_depth.measure_depth`, the default
:class:`~insitu.marking.engrave_depth.DepthSettings`), or one line saying why it cannot be
measured and what to do. A crossed scan (two passes of parallel lines,
:func:`~insitu.marking.engrave_passes.line_passes`) measures each pocket from each pass on its
own and combines their depths by their inverse variances; a pocket one pass cannot measure is
measured from the other. The report: :mod:`insitu.services.depth_report`."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import ConfigError, FormatError, MeasurementError
from insitu.formats.calibration import HeightCalibration
from insitu.formats.pointcloud import read_ply
from insitu.formats.sequence import Sequence
from insitu.marking.engrave_depth import DepthMap, DepthSettings, measure_depth
from insitu.marking.engrave_passes import OBLIQUE_DEG, LinePass, combine, line_passes, obliquity
from insitu.marking.engrave_stats import SHARED_MM
from insitu.marking.engrave_walls import line_direction
from insitu.services.common import Progress, camera_model
from insitu.services.pocket import depth_centres
from insitu.services.scan import scan_replay

PLANE_SCALE_MM = 30.0
"""Within this distance of the field's centre (world x, y = 0) the light plane alone holds a
depth's scale to ≈ 0.4 %; nearer the edge the head's distortion tilts the light and a depth
can be ≈ 4 % off (docs/accuracy.md, the height scale a depth carries)."""


@dataclass(frozen=True)
class DepthScan:
    """A scan's ``points`` (N, 3) world mm and the ``line`` (N,) each lies on;
    ``viewpoints`` (2, 3) world mm: the camera's centre and the head's pivot (None: not
    known, the cells a wall hides are not told apart); ``method``: how its heights were
    measured; ``first`` (2,): the direction of the lines recorded first (None: not known,
    insitu records along y first)."""

    points: np.ndarray
    line: np.ndarray
    viewpoints: np.ndarray | None
    method: str
    first: np.ndarray | None = None


FEW_LINES = "depth not stated"
"""How a note begins that a depth comes from fewer lines than a statement needs."""

OFF_FLOOR_SHARE = 0.02
"""Points left out as not floor beyond this share of a pocket's floor points are said."""


@dataclass(frozen=True)
class PassDepth:
    """A pocket measured from one pass of a crossed scan (``line_pass``): its depth ``map``,
    ``mean_mm`` and ``sem_mm`` (1σ), ``note``: why it cannot be stated (too few lines), and
    ``combined``: False when it is left out of the pocket's depth (slanted to its walls); or
    ``refused``: why not measured (``map`` None)."""

    line_pass: LinePass
    map: DepthMap | None = None
    mean_mm: float = float("nan")
    sem_mm: float = float("nan")
    note: str | None = None
    refused: str | None = None
    combined: bool = True


@dataclass(frozen=True)
class PocketDepth:
    """A pocket ``region`` (shapely, world mm) and its depth ``map`` with ``mean_mm``,
    ``sem_mm`` (1σ) and ``stated`` (2σ within the tolerance); ``note``: why a measured depth
    is not stated whatever its σ (its floor holds fewer lines than a statement needs), and
    what to do, and on a crossed scan which pass it was measured from alone, and why; or,
    when it could not be measured, ``refused``: why and what to do (``map`` None). On a
    crossed scan ``passes``: each pass's own (the depth theirs combined, ``map`` the first
    measured pass's)."""

    region: object
    map: DepthMap | None = None
    mean_mm: float = float("nan")
    sem_mm: float = float("nan")
    stated: bool = False
    note: str | None = None
    refused: str | None = None
    passes: tuple[PassDepth, ...] = ()

    @property
    def maps(self) -> list[DepthMap]:
        """The depth maps its depth comes from: each measured pass's combined, or its one."""
        if self.passes:
            return [p.map for p in self.passes if p.map is not None and p.combined]
        return [] if self.map is None else [self.map]

    @property
    def floor_lines(self) -> int:
        return sum(m.floor_lines for m in self.maps)

    @property
    def floor_points(self) -> int:
        return sum(len(m.floor) for m in self.maps)

    @property
    def off_floor(self) -> str | None:
        """A line saying how many of the points inside the pocket could not be its floor and
        were left out (:func:`~insitu.marking.engrave_stats.floor_like`), when they are more
        than :data:`OFF_FLOOR_SHARE` of its floor's points; None otherwise."""
        if self.map is None:
            return None
        n, floor = sum(m.not_floor for m in self.maps), self.floor_points
        if n <= OFF_FLOOR_SHARE * max(floor, 1):
            return None
        return (f"{n} points inside it lie above the top or far off its floor's depth (the "
                f"camera took another light path for the line, e.g. a mirrored one): left out "
                f"of its {floor} floor points; look at its depth map")

    @property
    def name(self) -> str:
        """The pocket as given: "x0 y0 x1 y1" (mm) of its outline's bounding box."""
        return " ".join(f"{v:g}" for v in np.round(self.region.bounds, 3))


def load_depth_scan(path: Path, height_cal: HeightCalibration | None = None,
                    model: str | None = None, progress: Progress | None = None) -> DepthScan:
    """A recorded scan folder replayed with a depth scan's centres (:func:`depth_centres`;
    heights by ``height_cal``, Method 2, else the light plane, Method 1), or a measured
    cloud (.ply) that keeps each point's line. ConfigError for anything else."""
    path = Path(path)
    if path.is_dir():
        seq = Sequence.open(path)
        result = scan_replay(path, height_cal, model, progress,
                             centres=depth_centres(height_cal))
        cam = camera_model(seq.camera)
        vp = np.array([cam.centre_world, [0.0, 0.0, seq.scan_head.pivot_height_mm]])
        drawn = [line for f in seq.frames if not f.survey for line in f.drawn()]
        first = np.subtract(drawn[0][1], drawn[0][0])[:2] if drawn else None
        return DepthScan(result.cloud.points, result.cloud.attributes["line"], vp,
                         result.summary.method, first)
    if path.suffix.lower() != ".ply":
        raise ConfigError(f"{path}: expected a recorded scan folder or a point cloud (.ply)")
    if height_cal is not None:
        raise ConfigError(f"{path}: a cloud's heights are measured already; --height-cal is "
                          "for a recorded scan folder")
    cloud = read_ply(path)
    if "line" not in cloud.attributes:
        raise FormatError(f"{path}: the cloud has no line index per point (`line`), which "
                          "the depth needs: measure from the recorded scan folder")
    return DepthScan(cloud.points, cloud.attributes["line"], None, "as the cloud was measured")


def plane_scale_warning(regions: list) -> str:
    """The warning for depths measured without a height calibration (Method 1): the scale
    it holds, and the pockets of ``regions`` (shapely, world mm) farther than
    :data:`PLANE_SCALE_MM` from the field's centre, where it holds less."""
    far = [r for r in regions if np.hypot(*r.centroid.coords[0]) > PLANE_SCALE_MM]
    where = ""
    if far:
        names = ", ".join(" ".join(f"{v:g}" for v in np.round(r.bounds, 1)) for r in far)
        where = (f"; the pocket{'s' if len(far) > 1 else ''} at {names} lie beyond it, where "
                 "the depth can be ≈ 4 % off")
    return (f"no height calibration: the depths' scale is the light plane's alone, ≈ 0.4 % "
            f"within {PLANE_SCALE_MM:g} mm of the field's centre{where}: give --height-cal")


PASSES = ("both", "1", "2")
"""Which passes of a crossed scan measure: both (their depths combined), or one: 1 the first
recorded, 2 the crossed one."""


def scan_passes(scan: DepthScan, which: str = "both", min_lines: int = 8
                ) -> tuple[list[LinePass], bool]:
    """The passes of ``scan`` (:func:`line_passes`) that ``which`` (:data:`PASSES`) asks for,
    and whether the scan is crossed (holds two). MeasurementError for a scan whose lines are
    neither one pass nor two, or when a crossed scan's pass asked for holds fewer than
    ``min_lines`` lines; ConfigError for pass 2 of a scan of one."""
    passes = line_passes(scan.points[:, :2], scan.line, scan.first)
    if which not in PASSES:
        raise ConfigError(f"--pass {which!r}: expected one of {', '.join(PASSES)}")
    if which == "2" and len(passes) == 1:
        raise ConfigError(f"--pass 2: the scan holds one pass of parallel lines (at "
                          f"{passes[0].angle_deg:.0f}° to x), no crossed one: give --pass 1 "
                          "or both")
    chosen = passes if which == "both" else [passes[int(which) - 1]]
    for p in chosen:
        if len(passes) > 1 and len(p.lines) < min_lines:
            other = next((q for q in passes if q is not p), None)
            also = f"measure from pass {other.number} alone (--pass {other.number}) or " \
                if other is not None and len(other.lines) >= min_lines else ""
            raise MeasurementError(f"{p.describe()} holds {len(p.lines)} lines, fewer than "
                                   f"the {min_lines} a pocket's floor needs: too few to be a "
                                   f"pass: {also}record the scan again")
    return chosen, len(passes) > 1


def finding_points(scan: DepthScan, which: str = "both") -> tuple[np.ndarray, np.ndarray]:
    """(points (N, 3), line (N,)) the pockets are found on
    (:func:`~insitu.services.depth_find.find_pockets`): a crossed scan's first pass ``which``
    asks for (pass 1 unless "2"), alone. The passes' heights differ by more than a shallow
    pocket (the simulated plate, Method 1: the crossed pass 62 µm above the first, its points
    twice as scattered), so both together hide it (its 0.05 mm pocket not found)."""
    passes, crossed = scan_passes(scan, which)
    if not crossed:
        return scan.points, scan.line
    on = passes[0].holds(scan.line)
    return scan.points[on], scan.line[on]


def measure_pockets(scan: DepthScan, regions: list, tolerance_mm: float,
                    settings: DepthSettings | None = None, which: str = "both"
                    ) -> list[PocketDepth]:
    """Each pocket of ``regions`` (shapely, world mm) measured on ``scan`` (``settings``:
    None, the defaults); stated when 2σ is within ``tolerance_mm``. A pocket that cannot be
    measured gets its reason. On a crossed scan each pass ``which`` asks for
    (:func:`scan_passes`) measures on its own, their depths combined
    (:func:`~insitu.marking.engrave_passes.combine`, :data:`SHARED_MM` common to both); a
    pocket one of them cannot measure is measured from the other."""
    settings = settings or DepthSettings()
    passes, crossed = scan_passes(scan, which, settings.min_lines)
    if not crossed:
        hull = shapely.MultiPoint(scan.points[:, :2]).convex_hull
        return [_measured(lambda r: _measure(scan, r, hull, tolerance_mm, settings), region)
                for region in regions]
    parts = []
    for p in passes:
        on = p.holds(scan.line)
        part = DepthScan(scan.points[on], scan.line[on], scan.viewpoints, scan.method)
        parts.append((p, part, shapely.MultiPoint(part.points[:, :2]).convex_hull))
    out = []
    for region in regions:
        each = []
        for p, part, hull in parts:
            got = _measured(lambda r, part=part, hull=hull: _measure(
                part, r, hull, tolerance_mm, settings), region)
            each.append(PassDepth(p, got.map, got.mean_mm, got.sem_mm, got.note,
                                  got.refused))
        out.append(_combined(region, each, tolerance_mm, aligned=which == "both"))
    return out


def _measured(measure, region) -> PocketDepth:
    try:
        return measure(region)
    except MeasurementError as e:
        return PocketDepth(region, refused=str(e))


def _combined(region, each: list[PassDepth], tolerance_mm: float, aligned: bool = True
              ) -> PocketDepth:
    """A pocket from its passes' depths: combined over those measured (``aligned``: of them,
    those whose lines cross its walls within :data:`OBLIQUE_DEG` as squarely as the best
    one's; the others said), stated when 2σ is within ``tolerance_mm`` and no pass of them
    has too few lines for a statement; or refused with each pass's reason."""
    done = [p for p in each if p.map is not None]
    if not done:
        return PocketDepth(region, refused="; ".join(
            f"{p.line_pass.describe()}: {p.refused}" for p in each), passes=tuple(each))
    notes = []
    if aligned and len(done) > 1:
        slant = [obliquity(p.line_pass.angle_deg, region) for p in done]
        best = done[int(np.argmin(slant))]
        for p, a in zip(done, slant):
            if a > min(slant) + OBLIQUE_DEG:
                notes.append(f"{p.line_pass.describe()} not combined "
                             f"({p.mean_mm:.4f} ± {p.sem_mm * 1e3:.1f} µm): its lines cross "
                             f"the walls at {a:.0f}° from square ({best.line_pass.describe()}: "
                             f"{min(slant):.0f}°), where the walls' zones read short; "
                             f"--pass {p.line_pass.number} uses it alone")
        done = [p for p, a in zip(done, slant) if a <= min(slant) + OBLIQUE_DEG]
        each = [p if p.map is None or p in done else replace(p, combined=False) for p in each]
    mean, sem = combine([(p.mean_mm, p.sem_mm) for p in done], SHARED_MM)
    notes += [f"{p.line_pass.describe()}: {p.note}" for p in done if p.note is not None]
    if any(p.map is None for p in each):
        names = " and ".join(p.line_pass.describe() for p in done)
        why = "; ".join(f"{p.line_pass.describe()} not: {p.refused}" for p in each
                        if p.map is None)
        notes.insert(0, f"measured from {names} alone ({why})")
    stated = 2 * sem <= tolerance_mm and all(p.note is None for p in done)
    return PocketDepth(region, done[0].map, mean, sem, bool(stated),
                       note="; ".join(notes) or None, passes=tuple(each))


def _measure(scan: DepthScan, region, hull, tolerance_mm: float, s: DepthSettings
             ) -> PocketDepth:
    if not hull.intersects(region):
        raise MeasurementError("it lies outside the scan: scan over it and "
                               f"{s.ring_mm:g} mm around it")
    if not hull.contains(region):
        raise MeasurementError("it reaches beyond the scan's points: scan over all of it and "
                               f"{s.ring_mm:g} mm around it")
    x0, y0, x1, y1 = region.bounds
    pad = s.ring_mm + s.cell_mm
    near = ((scan.points[:, 0] >= x0 - pad) & (scan.points[:, 0] <= x1 + pad)
            & (scan.points[:, 1] >= y0 - pad) & (scan.points[:, 1] <= y1 + pad))
    pts, line = scan.points[near], scan.line[near]
    inner = shapely.contains_xy(region.buffer(-s.parallel_band_mm), pts[:, 0], pts[:, 1])
    if inner.sum() < 5:
        raise MeasurementError(f"{int(inner.sum())} of the scan's points lie on its floor "
                               f"{s.parallel_band_mm:g} mm clear of its walls: check its box, "
                               "or scan it with lines closer together")
    dm = measure_depth(pts, line, region, s, viewpoints=scan.viewpoints)
    mean, sem = dm.mean_depth()
    if dm.floor_lines < s.min_lines:
        why = _too_few_lines(pts, line, region, dm, mean, s)
        if dm.floor_lines < 2:
            raise MeasurementError(why)
        return PocketDepth(region, dm, mean, sem, False, note=f"{FEW_LINES}: {why}")
    return PocketDepth(region, dm, mean, sem, bool(2 * sem <= tolerance_mm))


def _too_few_lines(pts: np.ndarray, line: np.ndarray, region, dm: DepthMap, depth: float,
                   s: DepthSettings) -> str:
    """Why a pocket's floor holds too few lines, and the spacing that gives it enough: its
    width across the lines less the parallel walls' zones at its depth (one of them a wall
    the camera may face), over :attr:`DepthSettings.min_lines`."""
    along = line_direction(pts[:, :2], line)
    across = np.array([along[1], -along[0]])
    xy = np.asarray(region.exterior.coords)
    pos = xy @ across
    depth = max(depth, 0.0) if np.isfinite(depth) else 0.0
    zone = max(s.parallel_band_mm, s.parallel_per_depth * depth)
    width = pos.max() - pos.min() - zone - max(zone, s.faced_band_mm)
    centres = np.sort(np.unique(np.round(
        [np.median(pts[line == k, :2] @ across) for k in np.unique(line)], 4)))
    spacing = float(np.median(np.diff(centres))) if len(centres) > 1 else float("nan")
    n = dm.floor_lines
    head = (f"{n} scan line{'s cross' if n != 1 else ' crosses'} its floor clear of the walls, fewer than "
            f"{s.min_lines} (the lines here {spacing:.2g} mm apart)")
    if width <= 0:
        return (f"{head}: at {depth:.2g} mm deep it is too narrow across the lines for its "
                "walls' zones; scan with the lines along its narrow side")
    return f"{head}: scan with lines ≤ {width / s.min_lines:.2g} mm apart"
