"""Pockets measured on a recorded scan (``insitu depth``): the recording replayed as a depth
scan replays it (centres across the line only, :data:`~insitu.services.pocket.DEPTH_CENTRES`),
or a measured cloud that keeps each point's line; each pocket's depth from its floor against
the top of the same lines (:func:`~insitu.marking.engrave_depth.measure_depth`, the default
:class:`~insitu.marking.engrave_depth.DepthSettings`), or one line saying why it cannot be
measured and what to do; the results and a depth map per pocket written as a report."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import ConfigError, FormatError, MeasurementError
from insitu.formats.atomic import atomic_folder, atomic_write_text
from insitu.formats.calibration import HeightCalibration
from insitu.formats.pointcloud import read_ply
from insitu.formats.sequence import Sequence
from insitu.marking.engrave_depth import DepthMap, DepthSettings, measure_depth
from insitu.marking.engrave_walls import line_direction
from insitu.services.common import Progress, camera_model
from insitu.services.engrave_report import depth_picture
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
    measured."""

    points: np.ndarray
    line: np.ndarray
    viewpoints: np.ndarray | None
    method: str


OFF_FLOOR_SHARE = 0.02
"""Points left out as not floor beyond this share of a pocket's floor points are said."""


@dataclass(frozen=True)
class PocketDepth:
    """A pocket ``region`` (shapely, world mm) and its depth ``map`` with ``mean_mm``,
    ``sem_mm`` (1σ) and ``stated`` (2σ within the tolerance); ``note``: why a measured depth
    is not stated whatever its σ (its floor holds fewer lines than a statement needs), and
    what to do; or, when it could not be measured, ``refused``: why and what to do (``map``
    None)."""

    region: object
    map: DepthMap | None = None
    mean_mm: float = float("nan")
    sem_mm: float = float("nan")
    stated: bool = False
    note: str | None = None
    refused: str | None = None

    @property
    def off_floor(self) -> str | None:
        """A line saying how many of the points inside the pocket could not be its floor and
        were left out (:func:`~insitu.marking.engrave_stats.floor_like`), when they are more
        than :data:`OFF_FLOOR_SHARE` of its floor's points; None otherwise."""
        if self.map is None:
            return None
        n, floor = self.map.not_floor, len(self.map.floor)
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
        return DepthScan(result.cloud.points, result.cloud.attributes["line"], vp,
                         result.summary.method)
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


def measure_pockets(scan: DepthScan, regions: list, tolerance_mm: float,
                    settings: DepthSettings | None = None) -> list[PocketDepth]:
    """Each pocket of ``regions`` (shapely, world mm) measured on ``scan`` (``settings``:
    None, the defaults); stated when 2σ is within ``tolerance_mm``. A pocket that cannot be
    measured gets its reason."""
    settings = settings or DepthSettings()
    hull = shapely.MultiPoint(scan.points[:, :2]).convex_hull
    out = []
    for region in regions:
        try:
            out.append(_measure(scan, region, hull, tolerance_mm, settings))
        except MeasurementError as e:
            out.append(PocketDepth(region, refused=str(e)))
    return out


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
        return PocketDepth(region, dm, mean, sem, False, note=f"depth not stated: {why}")
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


def write_report(folder: Path, pockets: list[PocketDepth], tolerance_mm: float,
                 source: str, method: str) -> None:
    """``folder`` (replaced as a whole, or left as it was on a failure): ``depth.json``
    (each pocket's outline, depth, 1σ, stated, floor lines and points, or why not measured)
    and ``pocket-K.png``, the depth map of each measured pocket K (from 1)."""
    rows = []
    with atomic_folder(folder) as tmp:
        for k, p in enumerate(pockets, start=1):
            row = {"pocket": p.name, "outline": np.round(
                np.asarray(p.region.exterior.coords)[:-1], 4).tolist()}
            if p.map is None:
                row["refused"] = p.refused
            else:
                picture = f"pocket-{k}.png"
                depth_picture(tmp / picture, p.map, p.mean_mm,
                              f"pocket {p.name}: {p.mean_mm * 1e3:.1f} ± "
                              f"{p.sem_mm * 1e3:.1f} µm (1σ)", centre="mean")
                row |= {"depth_mm": round(p.mean_mm, 6), "sigma_mm": round(p.sem_mm, 6),
                        "stated": p.stated, "floor_lines": p.map.floor_lines,
                        "floor_points": len(p.map.floor),
                        "not_floor_points": p.map.not_floor, "picture": picture}
                if p.note is not None:
                    row["note"] = p.note
            rows.append(row)
        atomic_write_text(tmp / "depth.json", json.dumps(
            {"scan": source, "method": method, "tolerance_mm": tolerance_mm,
             "pockets": rows}, indent=2) + "\n")
