"""A part's reference for locating it in a scan: dense points with normals in the part's own
frame, from a mesh (sampled evenly over the faces a camera above can see) or from a first scan
of the part (the table taken away; the part frame is then that scan's world frame).

The table is the lowest horizontal plane that holds a good share of a scan's points
(:func:`find_table`): points within ``band_mm`` above it, and everything below it, are the
table, not the part.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.spatial import ConvexHull, cKDTree

from insitu.errors import MeasurementError
from insitu.geometry.camera import CameraModel
from insitu.locate.edge_align import edge_samples
from insitu.locate.height_image import HeightImage, mesh_height_image, splat_image
from insitu.locate.image_edges import Outline, outline
from insitu.locate.outline_fit import OutlineFit, fit_outline, stamp
from insitu.locate.uncertainty import SCAN_REFERENCE_MM

UP_NZ = -0.2
"""Mesh faces whose normal's z is below this face the table: no camera above sees them."""
TOP_NZ = 0.5
"""Samples whose normal's z is above this are the part's top (what a scan must cover)."""
MAX_SAMPLES = 400_000


@dataclass(frozen=True, eq=False)
class PartReference:
    """A part in its own frame, mm: ``points`` (M, 3) float64 and unit ``normals`` (M, 3) of
    the surfaces visible from above; ``base_z_mm``: the height it rests on (a mesh's lowest
    z; a scan's table); ``kind``: "mesh" or "cloud"; ``source``: where it came from (a file
    name); ``spacing_mm``: the samples' mean spacing; ``heights``: the part and the table
    around it seen from above (:mod:`insitu.locate.height_image`); ``fitted``: a scan's
    outline fitted from its room-light frame (:mod:`insitu.locate.outline_fit`; None: a
    mesh's, or none fitted)."""

    points: np.ndarray
    normals: np.ndarray
    base_z_mm: float
    kind: str
    source: str
    spacing_mm: float
    heights: HeightImage
    fitted: OutlineFit | None = None

    @cached_property
    def tree(self) -> cKDTree:
        """KD-tree of ``points`` (built once, kept for every scan located against it)."""
        return cKDTree(self.points)

    @cached_property
    def top(self) -> np.ndarray:
        """(K, 3) upward-facing points thinned to about 0.5 mm: what a scan of the whole part
        covers (the coverage check)."""
        up = self.points[self.normals[:, 2] > TOP_NZ]
        return thin(up, 0.5)

    @cached_property
    def top_centroid(self) -> np.ndarray:
        """(2,) x, y mm: centre of the top's area, seen from above."""
        return self.top[:, :2].mean(axis=0) if len(self.top) else self.points[:, :2].mean(0)

    @property
    def outline_sigma_mm(self) -> float:
        """1σ of its outline's edges, each, mm: 0 for a mesh (exact), a scan's
        (:data:`insitu.locate.uncertainty.SCAN_REFERENCE_MM`) otherwise."""
        if self.kind == "mesh":
            return 0.0
        return SCAN_REFERENCE_MM["fitted" if self.fitted is not None else "splat"]

    @cached_property
    def rim(self) -> np.ndarray:
        """(M, 2) x, y mm: the corners of the top's convex hull seen from above — where a turn
        and a shift move the part furthest (the uncertainty at the part's rim)."""
        xy = self.top[:, :2] if len(self.top) >= 3 else self.points[:, :2]
        return xy[ConvexHull(xy).vertices]

    @cached_property
    def outline(self) -> Outline:
        """The edges of its top seen from above, for a room-light frame's edges: the fitted
        one, else the height image's (:func:`insitu.locate.image_edges.outline`)."""
        return self.fitted.outline if self.fitted is not None else outline(self.heights)

    def coarse(self, voxel_mm: float):
        """(points (K, 3), normals (K, 3), FPFH features (33, K)) on a ``voxel_mm`` grid, for
        the global step; computed once per voxel size."""
        cache = self.__dict__.setdefault("_coarse", {})
        if voxel_mm not in cache:
            cache[voxel_mm] = coarse_features(self.points, self.normals, voxel_mm)
        return cache[voxel_mm]


def thin(points: np.ndarray, cell_mm: float) -> np.ndarray:
    """One point (the first) of ``points`` (N, 3) per ``cell_mm`` cube."""
    if len(points) == 0:
        return points
    keys = np.floor(points / cell_mm).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return points[np.sort(first)]


def coarse_features(points: np.ndarray, normals: np.ndarray | None, voxel_mm: float):
    """``points`` thinned on a ``voxel_mm`` grid with normals (estimated and turned up when
    None) and FPFH features (radius 5 voxels): (points (K, 3), normals (K, 3), (33, K))."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points)))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(np.ascontiguousarray(normals))
    pcd = pcd.voxel_down_sample(voxel_mm)
    if normals is None:
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel_mm,
                                                                  max_nn=30))
        pcd.orient_normals_to_align_with_direction([0.0, 0.0, 1.0])
    else:
        pcd.normalize_normals()
    fpfh = o3d.pipelines.registration.compute_fpfh_feature(
        pcd, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel_mm, max_nn=100))
    return np.asarray(pcd.points), np.asarray(pcd.normals), np.asarray(fpfh.data)


def reference_from_mesh(vertices: np.ndarray, triangles: np.ndarray, source: str,
                        spacing_mm: float = 0.2, seed: int = 0) -> PartReference:
    """Sample the faces of a mesh (vertices (N, 3) mm, part frame; triangles (M, 3), outward
    normals by counter-clockwise order) evenly, about one point per ``spacing_mm``², keeping
    the faces a camera above can see (exact face normals). At most 400 k points: a larger
    part is sampled more sparsely. MeasurementError for a mesh without area."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(triangles, np.int64)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    cross = np.cross(b - a, c - a)
    area2 = np.linalg.norm(cross, axis=1)
    normal = cross / np.where(area2 > 0, area2, 1.0)[:, None]
    keep = (area2 > 0) & (normal[:, 2] > UP_NZ)
    total = area2[keep].sum() / 2
    if total <= 0:
        raise MeasurementError(f"{source}: the mesh has no faces a camera above could see")
    n = int(min(MAX_SAMPLES, max(2000, total / spacing_mm ** 2)))
    rng = np.random.default_rng(seed)
    idx = np.flatnonzero(keep)
    pick = idx[rng.choice(len(idx), n, p=area2[idx] / area2[idx].sum())]
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    pts = ((1 - s)[:, None] * a[pick] + (s * (1 - r2))[:, None] * b[pick]
           + (s * r2)[:, None] * c[pick])
    base = float(v[:, 2].min())
    return PartReference(pts, normal[pick], base, "mesh", source, float(np.sqrt(total / n)),
                         mesh_height_image(v, t, base))


def find_table(points: np.ndarray, band_mm: float = 0.5) -> float | None:
    """Height z, mm, of the table under a scan ``points`` (N, 3): the lowest 0.25 mm layer
    holding at least 5 % of the points (thinned to 1 mm) and flat (its points' heights spread
    less than ``band_mm``); None when the scan shows no table."""
    p = thin(points, 1.0)
    if len(p) < 20:
        return None
    z = p[:, 2]
    bins = np.arange(z.min(), z.max() + 0.5, 0.25)
    counts, edges = np.histogram(z, bins=bins)
    for k in np.flatnonzero(counts >= 0.05 * len(z)):
        near = z[np.abs(z - (edges[k] + 0.125)) < band_mm]
        zt = float(np.median(near))
        if np.percentile(np.abs(near - zt), 90) < band_mm / 2:
            return zt
    return None


def above_table(points: np.ndarray, table_z: float | None, band_mm: float) -> np.ndarray:
    """(N,) bool: the points of (N, 3) more than ``band_mm`` above the table (all of them when
    there is no table)."""
    if table_z is None:
        return np.ones(len(points), bool)
    return points[:, 2] > table_z + band_mm


def reference_from_cloud(points: np.ndarray, source: str, band_mm: float = 0.5,
                         table_z: float | None = None, image: np.ndarray | None = None,
                         camera: CameraModel | None = None,
                         lines: np.ndarray | None = None) -> PartReference:
    """A first scan of the part (N, 3) mm as its reference: the table (found, or at
    ``table_z``) taken away, normals estimated over 1 mm and turned up. The part frame is
    the scan's world frame. With ``image``, ``camera``'s room-light frame of the part as
    scanned, its outline is fitted there (:func:`insitu.locate.outline_fit.fit_outline`;
    checked by the scan's edges when ``lines`` (N,) gives each point's scan line) and its
    height image's edges redrawn on it. MeasurementError when no part stands above the
    table, or when the frame gives no outline."""
    import open3d as o3d

    pts = np.asarray(points, np.float64)
    table = find_table(pts) if table_z is None else table_z
    part = pts[above_table(pts, table, band_mm)]
    if len(part) < 100:
        raise MeasurementError(f"{source}: no part above the table (z = {table:.2f} mm) in "
                               "the reference scan")
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(part))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=1.0, max_nn=30))
    pcd.orient_normals_to_align_with_direction([0.0, 0.0, 1.0])
    spacing = float(np.median(cKDTree(part).query(part[::max(1, len(part) // 2000)], k=2)[0][:, 1]))
    base = float(table) if table is not None else float(part[:, 2].min())
    heights, fit = splat_image(pts, part, base, lines=lines), None
    if image is not None and camera is not None:
        scan = (None if lines is None else
                edge_samples(pts, np.asarray(lines), ~above_table(pts, table, band_mm), camera))
        fit = fit_outline(heights, image, camera, scan, part)
        if isinstance(fit, str):
            raise MeasurementError(f"{source}: its room-light frame gives no outline: {fit}")
        heights = stamp(heights, fit.anchored)
    return PartReference(part, np.asarray(pcd.normals), base, "cloud", source, spacing,
                         heights, fit)
