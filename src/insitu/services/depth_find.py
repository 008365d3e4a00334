"""Pockets found on a scan (``insitu depth`` without ``--pocket``): each point's depth below the
scan's top (a plane fitted robustly), its median over the points around each cell of a
raster; cells deeper than :data:`NOISE_SIGMAS` × the cells' robust σ, in connected regions of
at least :data:`MIN_AREA_MM2`, are a pocket. Its outline follows the cells deeper than half
its floor's depth (the floor set :func:`~insitu.marking.engrave_depth.measure_depth` takes
starts 0.1–0.4 mm inside the outline, so the outline must sit on the walls, where the depth
crosses half): their minimum rotated rectangle where they fill :data:`RECT_FILL` of it, else
their own outline. On synthetic turned pockets its corners lie within 2–11 µm of the
half-depth outline; the cells above the noise alone, 176–200 µm. Nothing in it assumes one
direction of lines, but a crossed scan's pockets are found on one pass
(:func:`~insitu.services.depth.finding_points`: the first): its two passes' heights differ by
more than a shallow pocket."""

from __future__ import annotations

import numpy as np
import shapely
from scipy import ndimage
from scipy.spatial import cKDTree

from insitu.marking.engrave_passes import line_angles

CELL_MM = 0.05
"""The raster the top's residuals are looked at on."""
RADIUS_MM = 0.3
NEIGHBOURS = 64
"""Each cell's value: the median depth of the (at most) this many points nearest its centre
within :data:`RADIUS_MM` (none with fewer than 3)."""
NOISE_SIGMAS = 3.0
"""A cell is below the top when its value exceeds this many of the cells' robust σ."""
MIN_AREA_MM2 = 0.5
RECT_FILL = 0.75
"""A region filling at least this share of its minimum rotated rectangle is a rectangle."""


def find_pockets(points: np.ndarray, line: np.ndarray) -> list:
    """The pockets (shapely polygons, world x, y mm), by x then y of their centres, of a
    scan's ``points`` (N, 3) mm on its lines ``line`` (N,) (a cell's neighbourhood grows to
    the points' spacing along the lines where they lie farther apart than
    :data:`RADIUS_MM`); lines of any direction, but of one pass (see the module docstring)."""
    depth = _below_top(points)
    radius = max(RADIUS_MM, _along_spacing(points, line))
    lo = points[:, :2].min(axis=0)
    shape = np.ceil((points[:, :2].max(axis=0) - lo) / CELL_MM).astype(int) + 1
    gx, gy = np.meshgrid(lo[0] + CELL_MM * np.arange(shape[0]),
                         lo[1] + CELL_MM * np.arange(shape[1]))
    dist, idx = cKDTree(points[:, :2]).query(np.column_stack([gx.ravel(), gy.ravel()]),
                                             k=NEIGHBOURS, distance_upper_bound=radius)
    near = np.where(np.isfinite(dist), depth[np.minimum(idx, len(depth) - 1)], np.nan)
    enough = np.isfinite(dist).sum(axis=1) >= 3
    value = np.full(len(near), np.nan)
    value[enough] = np.nanmedian(near[enough], axis=1)
    value = value.reshape(gx.shape)
    seen = value[np.isfinite(value)]
    sigma = 1.4826 * np.median(np.abs(seen - np.median(seen)))
    mask = np.nan_to_num(value) > NOISE_SIGMAS * max(sigma, 1e-4)
    mask = ndimage.binary_fill_holes(ndimage.binary_closing(mask, iterations=2))
    labels, n = ndimage.label(mask)
    found = []
    for k in range(1, n + 1):
        cells = labels == k
        if cells.sum() * CELL_MM ** 2 < MIN_AREA_MM2:
            continue
        core = ndimage.binary_erosion(cells, iterations=4)   # the floor, 0.2 mm in
        floor = np.median(value[core if core.any() else cells])
        cells = ndimage.binary_dilation(cells, iterations=4) & (np.nan_to_num(value) > floor / 2)
        found.append(_outline(gx[cells], gy[cells]))
    return sorted(found, key=lambda p: (round(p.centroid.x, 1), p.centroid.y))


def _along_spacing(points: np.ndarray, line: np.ndarray) -> float:
    """The median distance (mm) between a line's neighbouring points (each line in its own
    direction: a crossed scan's passes alike)."""
    ids, angle, _, _ = line_angles(points[:, :2], line)
    a = np.radians(angle[np.searchsorted(ids, line)])
    order = np.lexsort((points[:, 0] * np.cos(a) + points[:, 1] * np.sin(a), line))
    p, same = points[order, :2], line[order][1:] == line[order][:-1]
    gaps = np.linalg.norm(np.diff(p, axis=0), axis=1)[same]
    return float(np.median(gaps)) if len(gaps) else 0.0


def _below_top(points: np.ndarray, rounds: int = 6) -> np.ndarray:
    """(N,) each point's depth below the scan's top, a plane fitted to the points robustly
    (those within 3 robust σ of the last fit's median residual, so the pockets drop out: a
    first fit a large pocket pulls down leaves the top above the plane by more than its
    noise)."""
    a = np.column_stack([points[:, 0], points[:, 1], np.ones(len(points))])
    keep = np.ones(len(points), bool)
    for _ in range(rounds):
        coef = np.linalg.lstsq(a[keep], points[keep, 2], rcond=None)[0]
        res = points[:, 2] - a @ coef
        med = np.median(res[keep])
        mad = 1.4826 * np.median(np.abs(res[keep] - med))
        keep = np.abs(res - med) <= 3 * max(mad, 1e-4)
    return -(res - med)


def _outline(cx: np.ndarray, cy: np.ndarray):
    """The outline (shapely, world mm) of the region of cells centred at (``cx``, ``cy``)."""
    cells = shapely.MultiPoint(np.column_stack([cx, cy]))
    rect = cells.minimum_rotated_rectangle
    h = CELL_MM / 2 + 1e-6                           # the cells overlap: one region
    region = shapely.unary_union([shapely.box(x - h, y - h, x + h, y + h)
                                  for x, y in zip(cx, cy)])
    if rect.area <= 0 or region.area < RECT_FILL * rect.buffer(CELL_MM / 2,
                                                               join_style="mitre").area:
        parts = getattr(region, "geoms", [region])
        return max(parts, key=lambda g: g.area).simplify(CELL_MM / 2)
    return rect


def describe(region) -> str:
    """"2.00 × 2.00 mm at (2.50, 0.00), turned 20.0°" for a rectangle, else its area."""
    c = np.asarray(region.exterior.coords)
    if len(c) != 5:
        return f"{region.area:.2f} mm² around ({region.centroid.x:.2f}, {region.centroid.y:.2f})"
    a, b = np.linalg.norm(c[1] - c[0]), np.linalg.norm(c[2] - c[1])
    turn = (np.degrees(np.arctan2(*(c[1] - c[0])[::-1])) + 45.0) % 90.0 - 45.0
    return (f"{a:.2f} × {b:.2f} mm at ({region.centroid.x:.2f}, {region.centroid.y:.2f}), "
            f"turned {turn:.1f}°")
