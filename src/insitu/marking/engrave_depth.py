"""How deep a pocket is, measured by the scan lines that cross it: its floor and the top
around it from the same lines, per point and as a map over the pocket's cells.

The top: the scan's points outside the pocket, farther than ``wall_band_mm`` from its outline
and within ``ring_mm`` of it, fit a plane z(x, y) (a quadratic only where the top is curved:
:mod:`insitu.marking.engrave_top`) plus an offset per line, shrunk towards 0 by the evidence
the line's own top points give (a line's height error is shared by its floor points, so the
floor is referred to the top of the same lines). A floor point's depth is top(x, y) +
offset(line) − z.

The wall's neighbourhood: a point within ``wall_band_mm`` of the outline is not top; the
floor counts only beyond the walls' bias zones, wider for the walls the scan lines cross than
for those parallel to them, and growing with the depth
(:mod:`insitu.marking.engrave_walls`), and beyond where each kind of wall reaches the floor's
level as measured (walls that slope wide: :func:`~insitu.marking.engrave_walls.wall_feet`).
Points inside the outline that cannot be floor (above the top, or far off the floor's depth:
:func:`~insitu.marking.engrave_stats.floor_like`) are left out first and counted. A floor
point's error is shared along its line (the speckle of the floor it crosses, about 0.01 mm):
a floor crossed by fewer than ``min_lines`` lines with trusted points is not measured at
all.

The lines: a line's floor points also share an error its top points do not see (the floor
it crosses); each line's share, estimated from its points' residuals against the other lines'
around them, is removed before the map is made; what is left of it counts in the cells'
standard errors, which count lines, not points (:mod:`insitu.marking.engrave_stats`).

The marks' frame: the points are first shifted along the lines so that the walls they cross
sit on the outline (the camera's calibration places them ~0.1 mm off there:
:mod:`insitu.marking.engrave_register`), so each cell reads the floor its passes go to and
the floor kept clear of a crossed wall is clear of the wall itself (unregistered, the floor
within 0.1 mm of it, 13–75 µm short, pulled the simulated plate's pockets short).

The map: a cell's depth is the Gaussian-weighted mean of the floor points around its centre
(σ ``kernel_mm``), with its standard error (and the error of the kernel's averaging over more
than the cell, from the map's own texture: :func:`~insitu.marking.engrave_stats.texture_var`);
each cell of the pocket is
  measured   — enough trusted floor points around it (``min_points`` effective), its centre
               beyond the bias zone at its depth: the one state whose depth can be trusted;
  wall       — its centre within the band (``parallel_band_mm`` of a wall parallel to the
               lines): the value the kernel brings from the floor inside;
  hidden     — the camera (or the beam) cannot reach it past the wall at the depth around it
               (a wall cell too: whatever the kernel brings it comes from the floor beside);
  unmeasured — too few trusted points or lines, or its centre within the bias zone at its
               depth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from insitu.errors import MeasurementError
from insitu.marking.engrave_register import wall_shift
from insitu.marking.engrave_stats import (
    cell_means,
    floor_like,
    line_sem,
    line_terms,
    texture_var,
)
from insitu.marking.engrave_top import top_model
from insitu.marking.engrave_walls import (
    MAX_CROSSING,
    beyond_feet,
    clear,
    line_axes,
    line_direction,
    unreachable,
    wall_feet,
)

STATES = ("measured", "wall", "hidden", "unmeasured")
MEASURED, WALL, HIDDEN, UNMEASURED = range(4)
OUTSIDE = -1
_RASTER_MM = 0.01


@dataclass(frozen=True)
class DepthSettings:
    """``wall_band_mm``: points this close to the outline are left out (floor and top);
    ``ring_mm``: top points up to this far outside; ``cell_mm``: the map's cells;
    ``kernel_mm``: σ of the weights that average floor points into a cell; ``min_points``:
    effective points for a cell to count as measured; ``bias_per_depth``: the band grows by
    this many mm per mm of depth for the floor's points and the measured cells' centres;
    ``parallel_band_mm``, ``parallel_per_depth``: the zone of a wall parallel to the scan
    lines, the larger of the two (see the module docstring); ``faced_band_mm``: the zone of
    a parallel wall facing the camera (the floor's line mirrored in it pulls the lines
    beside it short on a specular blank, :mod:`~insitu.marking.engrave_walls`);
    ``min_lines``: scan lines with trusted floor points for any cell to count as measured;
    ``register_mm``: the points are shifted along the lines to put the walls they cross on the
    outline, the shift searched within ± this (0: not registered;
    :mod:`~insitu.marking.engrave_register`; the simulated plate's spent scans, 212 pockets:
    mean error −1.11 → −0.36 µm, |err|/σ rms 1.13 → 1.03)."""

    wall_band_mm: float = 0.2
    bias_per_depth: float = 0.25
    parallel_band_mm: float = 0.1
    parallel_per_depth: float = 0.55
    faced_band_mm: float = 0.4
    min_lines: int = 8
    ring_mm: float = 2.0
    cell_mm: float = 0.25
    kernel_mm: float = 0.2
    min_points: float = 8.0
    register_mm: float = 0.4


@dataclass(frozen=True)
class PocketCells:
    """The cells over a pocket: ``origin`` (x, y) world mm of cell (0, 0)'s centre,
    ``cell_mm`` apart, ``inside`` (ny, nx) bool: the cell's centre lies in the pocket,
    ``edge_mm`` (ny, nx): its centre's distance to the outline (> 0 inside)."""

    origin: np.ndarray
    cell_mm: float
    inside: np.ndarray
    edge_mm: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.inside.shape

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(ny, nx) world x and y of the cells' centres."""
        ny, nx = self.shape
        return np.meshgrid(self.origin[0] + self.cell_mm * np.arange(nx),
                           self.origin[1] + self.cell_mm * np.arange(ny))

    def index(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) of the cell holding each world point, clipped to the grid."""
        ny, nx = self.shape
        col = np.clip(np.round((np.asarray(x) - self.origin[0]) / self.cell_mm), 0, nx - 1)
        row = np.clip(np.round((np.asarray(y) - self.origin[1]) / self.cell_mm), 0, ny - 1)
        return row.astype(int), col.astype(int)


class Outline:
    """A pocket's region (shapely, world x, y mm) rasterised at 0.01 mm with its signed
    distance: :meth:`distance` of any point to the outline, > 0 inside."""

    def __init__(self, region, margin_mm: float):
        if region.is_empty:
            raise MeasurementError("the pocket's region is empty")
        self.region = region
        x0, y0, x1, y1 = region.bounds
        self.origin = np.array([x0 - margin_mm, y0 - margin_mm])
        nx = int(np.ceil((x1 - x0 + 2 * margin_mm) / _RASTER_MM)) + 1
        ny = int(np.ceil((y1 - y0 + 2 * margin_mm) / _RASTER_MM)) + 1
        gx, gy = np.meshgrid(self.origin[0] + _RASTER_MM * np.arange(nx),
                             self.origin[1] + _RASTER_MM * np.arange(ny))
        inside = shapely.contains_xy(region, gx, gy)
        self._signed = (distance_transform_edt(inside) - distance_transform_edt(~inside)
                        ) * _RASTER_MM
        self._walls: dict = {}

    def distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(N,) signed distance (mm) of world points to the outline; −inf off the raster."""
        return self._sample(self._signed, x, y, -np.inf)

    def _sample(self, raster: np.ndarray, x, y, off: float) -> np.ndarray:
        ny, nx = raster.shape
        col = np.round((np.asarray(x) - self.origin[0]) / _RASTER_MM).astype(int)
        row = np.round((np.asarray(y) - self.origin[1]) / _RASTER_MM).astype(int)
        ok = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
        out = np.full(np.shape(x), off)
        out[ok] = raster[row[ok], col[ok]]
        return out

    def wall_distances(self, x, y, along, camera=None) -> tuple[np.ndarray, ...]:
        """(distance to the walls the scan lines cross, to the walls parallel to them, to
        the parallel walls facing ``camera``), mm, of world points (``x``, ``y``) inside the
        pocket; ``along`` (2,): the lines' direction; ``camera`` (2,): the camera's world x, y
        (None: no wall faces it). A wall is parallel when its normal lies within 45° of
        across the lines; it faces the camera when its normal into the pocket points to the
        camera's side."""
        key = (round(float(along[0]), 2), round(float(along[1]), 2),
               None if camera is None else (round(float(camera[0])), round(float(camera[1]))))
        if key not in self._walls:
            outside = self._signed <= 0
            edge = outside & (distance_transform_edt(outside) <= 1.5)
            gy, gx = np.gradient(self._signed)
            norm = np.maximum(np.hypot(gx, gy), 1e-12)
            parallel = edge & (np.abs(gx * along[0] + gy * along[1]) / norm < np.sqrt(0.5))
            faced = np.zeros_like(parallel)
            if camera is not None:
                cx = np.asarray(camera[0], float) - self.origin[0] - _RASTER_MM * np.arange(
                    self._signed.shape[1])[None, :]
                cy = np.asarray(camera[1], float) - self.origin[1] - _RASTER_MM * np.arange(
                    self._signed.shape[0])[:, None]
                faced = parallel & (gx * cx + gy * cy > 0)
            self._walls[key] = tuple(distance_transform_edt(~w) * _RASTER_MM if w.any() else
                                     np.full(w.shape, np.inf) for w in (edge & ~parallel,
                                                                        parallel, faced))
        return tuple(self._sample(w, x, y, 0.0) for w in self._walls[key])

    def cells(self, cell_mm: float) -> PocketCells:
        """The cells over the region (its bounding box, one cell beyond)."""
        x0, y0, x1, y1 = self.region.bounds
        origin = np.floor(np.array([x0, y0]) / cell_mm) * cell_mm - cell_mm / 2
        nx = int(np.ceil((x1 - origin[0]) / cell_mm)) + 1
        ny = int(np.ceil((y1 - origin[1]) / cell_mm)) + 1
        gx, gy = np.meshgrid(origin[0] + cell_mm * np.arange(nx),
                             origin[1] + cell_mm * np.arange(ny))
        edge = self.distance(gx, gy)
        return PocketCells(origin, cell_mm, edge > 0, edge)


@dataclass(frozen=True)
class DepthMap:
    """A pocket measured: per cell (``cells``' grid) its ``depth`` mm (NaN: none), standard
    error ``sem`` mm, effective ``points`` and ``state`` (an index of :data:`STATES`,
    :data:`OUTSIDE` off the pocket); ``floor`` (M, 3): each floor point's x, y and depth;
    ``top_rms``: the top model's residual rms, ``point_sigma``: a floor point's depth
    scatter (robust), ``mean_sem``: the standard error of :meth:`mean_depth` (the floor's
    lines as independent samples or, where larger, the scatter along them; the top's own
    error and the lines' shared one beside it: :func:`~.engrave_stats.line_sem`; NaN: from
    ``point_sigma``),
    ``floor_lines``: the scan lines the floor's points lie on; ``shift_mm``: the shift along
    the lines taken off the points (:attr:`DepthSettings.register_mm`); ``not_floor``: the
    points inside the pocket that cannot be its floor, left out (:func:`floor_like`)."""

    cells: PocketCells
    depth: np.ndarray
    sem: np.ndarray
    points: np.ndarray
    state: np.ndarray
    floor: np.ndarray
    top_rms: float
    point_sigma: float
    mean_sem: float = float("nan")
    floor_lines: int = 0
    shift_mm: float = 0.0
    not_floor: int = 0

    def mean_depth(self) -> tuple[float, float]:
        """The floor's mean depth and its standard error, mm (points beyond 4σ left out)."""
        d = self.floor[:, 2]
        if len(d) == 0:
            return float("nan"), float("nan")
        med = np.median(d)
        keep = np.abs(d - med) <= 4 * max(self.point_sigma, 1e-6)
        sem = self.mean_sem if np.isfinite(self.mean_sem) else (
            self.point_sigma / np.sqrt(max(keep.sum(), 1)))
        return float(d[keep].mean()), float(sem)

    def pocket_depth(self, tolerance_mm: float, min_lines: int = 8) -> tuple[float, float]:
        """:meth:`mean_depth`, or MeasurementError when it is not known to ``tolerance_mm``
        (2 standard errors) or its floor beyond the walls' bias zones holds fewer than
        ``min_lines`` scan lines."""
        mean, sem = self.mean_depth()
        if self.floor_lines < min_lines or not 2 * sem <= tolerance_mm:
            raise MeasurementError(
                f"the pocket's depth is known to ±{2e3 * sem:.1f} µm (2σ) from "
                f"{self.floor_lines} scan lines on its floor clear of the walls, not to the "
                f"±{tolerance_mm * 1e3:.1f} µm asked: scan its lines closer, with a longer "
                "exposure, or a wider pocket")
        return mean, sem

    def count(self, state: int) -> int:
        return int((self.state == state).sum())


def measure_depth(points: np.ndarray, line: np.ndarray, region, settings: DepthSettings,
                  outline: Outline | None = None, cells: PocketCells | None = None,
                  viewpoints: np.ndarray | None = None,
                  expected_mm: np.ndarray | None = None) -> DepthMap:
    """The pocket ``region`` (shapely, world mm) measured by a scan's ``points`` (N, 3) mm,
    ``line`` (N,) the scan line of each. ``viewpoints`` (K, 3): where the camera and the beam
    come from (world mm), for the cells they cannot reach past a wall (None: not checked);
    ``expected_mm`` (cells' grid): the depth a model expects where no cell is measured (None:
    the nearest measured cell's). MeasurementError when the scan has too few top or floor
    points."""
    s = settings
    outline = outline or Outline(region, s.ring_mm + s.cell_mm)
    cells = cells or outline.cells(s.cell_mm)
    dist, top, floor = _split(points, outline, s)
    near = dist >= -s.ring_mm
    crossing = line_axes(points[near, :2], line[near])[1]
    if crossing > MAX_CROSSING:
        raise MeasurementError(f"the scan's lines over the pocket run in more than one direction "
                               f"(spread across them {crossing:.2f} of along, at most "
                               f"{MAX_CROSSING}: a crossed scan?): measure the pocket from one "
                               "pass of parallel lines")
    top_fit = top_model(points[top], line[top])
    shift = 0.0
    if s.register_mm > 0:
        along = line_direction(points[floor, :2], line[floor])
        shift = wall_shift(points[:, 0], points[:, 1], top_fit.at(points, line) - points[:, 2],
                           along, outline, s.register_mm)
        points = points.copy()
        points[:, :2] -= shift * along
        dist, top, floor = _split(points, outline, s)
        top_fit = top_model(points[top], line[top])
    d = top_fit.at(points[floor], line[floor]) - points[floor, 2]
    real = floor_like(d, line[floor], top_fit.rms)
    floor = np.flatnonzero(floor)[real]
    d = d[real]
    zone_d = _local_median(points[floor, :2], d, s.kernel_mm)
    along = line_direction(points[floor, :2], line[floor])
    camera = None if viewpoints is None else viewpoints[0][:2]
    wd = outline.wall_distances(points[floor, 0], points[floor, 1], along, camera)
    feet = wall_feet(wd, d)
    trusted = clear(wd, zone_d, s) & beyond_feet(wd, feet)
    fx, fy, d = points[floor, 0][trusted], points[floor, 1][trusted], d[trusted]
    fline = np.unique(line[floor][trusted], return_inverse=True)[1]
    raw = d
    d, line_var = line_terms(fx, fy, d, fline, s.kernel_mm)
    depth, sem, neff, sigma, keep = cell_means(cells, fx, fy, d, s.kernel_mm, fline,
                                                line_var)
    state = np.full(cells.shape, OUTSIDE, np.int8)
    state[cells.inside] = UNMEASURED
    enough = np.unique(line[floor][trusted]).size >= s.min_lines
    ok = cells.inside & (neff >= s.min_points) & enough
    near = _nearest_depth(depth, ok) if expected_mm is None else np.where(ok, depth,
                                                                          expected_mm)
    walls = outline.wall_distances(*cells.centres(), along, camera)
    state[ok & clear(walls, near, s) & beyond_feet(walls, feet)] = MEASURED
    state[cells.inside & ~clear(walls, 0.0, s)] = WALL
    if viewpoints is not None:
        blocked = unreachable(cells, near, outline, viewpoints)
        state[(state == UNMEASURED) & blocked] = HIDDEN
        state[(state == WALL) & blocked] = HIDDEN
    depth = np.where(state == OUTSIDE, np.nan, np.where(neff > 0, depth, np.nan))
    sem = np.sqrt(sem ** 2 + texture_var(depth, state == MEASURED, cells.cell_mm, s.kernel_mm))
    floor_pts = np.column_stack([fx, fy, d])[keep]
    pos = np.column_stack([fx, fy])[keep] @ along
    mean_sem = line_sem(raw[keep], fline[keep], pos, top_fit.sem(floor_pts))
    return DepthMap(cells, depth, sem, neff, state, floor_pts, top_fit.rms, sigma, mean_sem,
                    int(np.unique(fline[keep]).size), shift, int((~real).sum()))


def _split(points: np.ndarray, outline: Outline, s: DepthSettings):
    """(N,) each point's distance to the outline, and which are top and which floor;
    MeasurementError when too few are either."""
    dist = outline.distance(points[:, 0], points[:, 1])
    top = (dist <= -s.wall_band_mm) & (dist >= -s.ring_mm)
    floor = dist >= min(s.wall_band_mm, s.parallel_band_mm)
    if top.sum() < 20:
        raise MeasurementError(f"the scan has {int(top.sum())} points on the top around the "
                               "pocket: scan beyond its outline")
    if floor.sum() < 5:
        raise MeasurementError(f"the scan has {int(floor.sum())} points on the pocket's floor")
    return dist, top, floor


def _local_median(xy: np.ndarray, d: np.ndarray, radius_mm: float) -> np.ndarray:
    """(N,) the median of ``d`` over the points within ``radius_mm`` of each (``xy`` (N, 2)):
    the depth a point's bias zone is set by, not its own noisy one (which would keep the
    shallow-reading points near a wall and drop the deep-reading ones)."""
    near = cKDTree(xy).query_ball_point(xy, radius_mm)
    return np.array([np.median(d[i]) for i in near])


def _nearest_depth(depth: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(ny, nx) each cell's depth, or its nearest measured cell's where it has none."""
    if not ok.any():
        return np.zeros(depth.shape)
    _, (ri, ci) = distance_transform_edt(~ok, return_indices=True)
    return np.where(ok, depth, depth[ri, ci])
