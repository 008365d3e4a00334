"""Projection of placed polylines onto the measured surface (Li et al. §2.4, Case 3).

Input polylines are already placed in world x, y: list of (N, 2) float arrays, mm. Output:
one (N', 3) array per polyline, world frame, mm — the 3-D targets of a mark job.

* planar — every polyline is densified (step ≤ the cloud's point spacing) and each point
  takes its z from the neighbouring cloud points (robust local plane, :mod:`.surface`);
  x, y are kept.
* wrap — equal arc length: lengths measured along the surface equal the pattern's. In a frame
  (a, b) rotated by the unroll direction about the anchor, the pattern's (u, v) map to the
  surface by integrating arc length along b through the anchor (v → b), then along a on that
  row (u → a). Exact for developable surfaces unrolled across their axis (cylinders, cones'
  rulings aside, tilted planes); elsewhere the metric distortion is measured and reported as
  ``max_stretch`` = max |σ − 1| over the pattern of the mapping's singular values σ. The
  direction is the one with the least stretch among x, y, the anchor's principal curvature
  and slope directions, unless given.

Both modes leave out what lies in the strip between two levels of a step that neither level
measured (:class:`~.surface.SurfaceSample` ``unmeasured``): the path is split there and the
laser is off across it, so every target lies on a measured level within its measured extent.
``Projection.unmarked_mm`` says how much of the pattern's path that left out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.ndimage import map_coordinates

from insitu.errors import MeasurementError, SafetyError
from insitu.formats.pointcloud import PointCloud
from insitu.marking.surface import Surface, level_jumps

_MARGIN_MM = 5.0
_MAX_GRID = 200


@dataclass(frozen=True)
class Projection:
    """``paths``: (N_i, 3) mm per input polyline. Per point, concatenated in path order:
    ``gap_mm`` to the nearest cloud point and the local ``slope_deg`` (for the checks).
    ``step_mm``: densification step; ``max_stretch``: worst metric distortion (wrap; 0 for
    planar); ``direction_deg``: wrap unroll direction (angle of a from +x). ``path_mm``: the
    pattern's path length (x, y), ``unmarked_mm`` of it left out at walls (across a wall and
    over the strip beside it that neither level measured)."""

    paths: list[np.ndarray]
    mode: str
    step_mm: float
    hole_radius_mm: float
    gap_mm: np.ndarray
    slope_deg: np.ndarray
    max_stretch: float = 0.0
    direction_deg: float | None = None
    anchor: tuple[float, float] | None = None
    extra: dict = field(default_factory=dict)
    path_mm: float = 0.0
    unmarked_mm: float = 0.0

    @property
    def points(self) -> np.ndarray:
        """(N, 3) all points, path order."""
        return np.vstack(self.paths) if self.paths else np.zeros((0, 3))

    @property
    def unmarked_fraction(self) -> float:
        """Share of the pattern's path left unmarked at walls, 0 … 1."""
        return self.unmarked_mm / self.path_mm if self.path_mm > 0 else 0.0


def _pack(polylines) -> tuple[np.ndarray, np.ndarray]:
    """list of (N_i, D) → (ΣN, D) and offsets (P + 1,); a flat list of numbers is (N, 2)."""
    arrs = [np.asarray(p, np.float64) for p in polylines]
    arrs = [a if a.ndim == 2 else a.reshape(-1, 2) for a in arrs]
    if any(len(a) == 0 for a in arrs):
        raise ValueError("project: a polyline has no points")
    off = np.concatenate([[0], np.cumsum([len(a) for a in arrs])]).astype(np.int64)
    return (np.vstack(arrs) if arrs else np.zeros((0, 2))), off


def densify_packed(pts: np.ndarray, off: np.ndarray, step: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Insert points so no segment is longer than ``step`` (mm). Packed form in and out:
    points (N, D), offsets (P + 1,). Original vertices are kept."""
    n = len(pts)
    if n == 0:
        return pts, off
    last = np.zeros(n, bool)
    last[off[1:] - 1] = True                       # last vertex of each path: no segment after
    seg_len = np.zeros(n)
    seg_len[:-1] = np.linalg.norm(pts[1:] - pts[:-1], axis=1)
    seg_len[last] = 0.0
    k = np.where(last, 1, np.maximum(np.ceil(seg_len / step - 1e-9), 1)).astype(np.int64)
    start = np.repeat(np.arange(n), k)
    frac = (np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)) / np.repeat(k, k)
    nxt = np.minimum(start + 1, n - 1)
    out = pts[start] + frac[:, None] * np.where(np.repeat(last, k)[:, None], 0.0,
                                                pts[nxt] - pts[start])
    new_off = np.concatenate([[0], np.cumsum(k)])[off]
    return out, new_off


def densify(polylines, step_mm: float) -> list[np.ndarray]:
    """Each (N, D) polyline with points inserted so that no segment exceeds ``step_mm``."""
    pts, off = _pack(polylines)
    out, o = densify_packed(pts, off, step_mm)
    return [out[o[i]:o[i + 1]] for i in range(len(o) - 1)]


def _region(pts: np.ndarray, margin: float, around=None) -> tuple[float, float, float, float]:
    if around is None:
        lo, hi = pts.min(0), pts.max(0)
    else:
        r = float(np.max(np.linalg.norm(pts - around, axis=1))) if len(pts) else 0.0
        lo, hi = np.asarray(around) - r, np.asarray(around) + r
    return (lo[0] - margin, hi[0] + margin, lo[1] - margin, hi[1] + margin)


def surface_for(polylines, cloud: PointCloud | np.ndarray, anchor=None, **kw) -> Surface:
    """A :class:`Surface` of the cloud cropped to the polylines (around ``anchor`` if given)."""
    pts, _ = _pack(polylines)
    region = _region(pts, _MARGIN_MM, anchor)
    try:
        return Surface(cloud, region=region, **kw)
    except MeasurementError:
        c = pts.mean(0) if len(pts) else np.zeros(2)
        raise SafetyError(f"pattern point at (x, y) = ({c[0]:.3f}, {c[1]:.3f}) mm is outside "
                          "the scanned area (no measured points under the pattern)",
                          where_mm=(c[0], c[1])) from None


def _split(arr: np.ndarray, off: np.ndarray) -> list[np.ndarray]:
    return [arr[off[i]:off[i + 1]] for i in range(len(off) - 1)]


def _xy_length(xyz: np.ndarray, off: np.ndarray) -> float:
    """Summed x-y length of the paths of packed points (N, ≥ 2), offsets (P + 1,), mm."""
    if len(xyz) < 2:
        return 0.0
    seg = np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1)
    inside = np.ones(len(seg), bool)
    inside[off[1:-1] - 1] = False
    return float(seg[inside].sum())


def _measured(xyz: np.ndarray, cuts: np.ndarray, unmeasured: np.ndarray, *per_point
              ) -> tuple[list[np.ndarray], float, list[np.ndarray]]:
    """Split the packed paths (points (N, 3), offsets ``cuts``) where they enter the strip
    that neither level measured and leave those points out; a piece of a longer path left
    with one point is left out too. Returns the paths, their length (x-y, mm) and each of
    ``per_point`` (N,) arrays for the points kept; SafetyError when nothing is left."""
    n = len(xyz)
    lens = np.diff(cuts)
    keep = ~unmeasured
    for _ in range(2):                   # the second pass: the single points the first left
        start = np.zeros(n, bool)
        start[cuts[:-1]] = True
        start[1:] |= keep[1:] & ~keep[:-1]
        kept = np.flatnonzero(keep)
        off = np.append(np.flatnonzero(start[kept]), len(kept))
        single = kept[off[:-1][np.diff(off) == 1]]
        single = single[np.repeat(lens, lens)[single] > 1]
        if len(single) == 0:
            break
        keep[single] = False
    if n and not len(kept):
        x, y = xyz[0, :2]
        raise SafetyError(f"pattern point at (x, y) = ({x:.3f}, {y:.3f}) mm lies beside a step, "
                          "where the cloud does not show the surface (nothing of the pattern "
                          "is left to mark)", where_mm=(x, y))
    out = xyz[kept]
    return _split(out, off), _xy_length(out, off), [a[kept] for a in per_point]


def project_planar(polylines, cloud: PointCloud | np.ndarray | Surface,
                   step_mm: float | None = None, *, anchor=None,
                   direction_deg: float | None = None) -> Projection:
    """Keep x, y; z from the surface. Polylines: list of (N, 2) world mm. A polyline that
    crosses a step is split where it drops from one level to the other (the laser is off
    across the wall), so there may be more paths than polylines. ``anchor`` and
    ``direction_deg`` (the projectors' common keywords) do not matter here."""
    pts, off = _pack(polylines)
    surf = cloud if isinstance(cloud, Surface) else surface_for(polylines, cloud)
    step = float(step_mm or surf.spacing_mm)
    dense, doff = densify_packed(pts, off, step)
    s = surf.sample(dense)
    xyz = np.column_stack([dense, s.z])
    jump = level_jumps(xyz)
    jump[doff[1:-1] - 1] = False                     # between two polylines: not a jump
    cuts = np.union1d(doff, np.flatnonzero(jump) + 1)
    paths, marked, (gap, slope) = _measured(xyz, cuts, s.unmeasured, s.gap_mm, s.slope_deg)
    total = _xy_length(xyz, doff)
    return Projection(paths, "planar", step, surf.hole_radius_mm, gap, slope,
                      path_mm=total, unmarked_mm=total - marked)


# ----------------------------------------------------------------------------- wrap
class _GradientGrid:
    """Surface gradient (dz/dx, dz/dy) sampled on a square x-y grid, bilinear in between;
    0 where the cloud has no data (those points are refused by the checks anyway)."""

    def __init__(self, surf: Surface, centre: np.ndarray, half: float, h: float):
        n = int(np.ceil(half / h))
        self.x0, self.y0, self.h = centre[0] - n * h, centre[1] - n * h, h
        ax = np.arange(-n, n + 1) * h
        gx, gy = np.meshgrid(centre[0] + ax, centre[1] + ax)
        g = surf.sample(np.column_stack([gx.ravel(), gy.ravel()]), k=4 * surf.k).grad
        g = np.nan_to_num(g, nan=0.0)
        self.g = [g[:, i].reshape(gx.shape) for i in range(2)]

    def __call__(self, xy: np.ndarray) -> np.ndarray:
        coords = [(xy[..., 1] - self.y0) / self.h, (xy[..., 0] - self.x0) / self.h]
        return np.stack([map_coordinates(g, coords, order=1, mode="nearest") for g in self.g],
                        -1)


class ArcLengthMap:
    """Equal-arc-length map (u, v) → (x, y) about ``anchor`` in the frame turned by
    ``theta_rad``; u, v: pattern offsets from the anchor along a, b, mm."""

    def __init__(self, grad: _GradientGrid, anchor: np.ndarray, theta_rad: float,
                 u_range: tuple[float, float], v_range: tuple[float, float], h: float):
        self.anchor, self.h = np.asarray(anchor, float), h
        c, s = np.cos(theta_rad), np.sin(theta_rad)
        self.ea, self.eb = np.array([c, s]), np.array([-s, c])
        ia = np.arange(int(np.floor(u_range[0] / h)) - 2, int(np.ceil(u_range[1] / h)) + 3)
        ib = np.arange(int(np.floor(v_range[0] / h)) - 2, int(np.ceil(v_range[1] / h)) + 3)
        self.a, self.b = ia * h, ib * h
        i0, j0 = int(np.argmin(np.abs(self.a))), int(np.argmin(np.abs(self.b)))
        # along b through the anchor
        col = self.anchor + self.b[:, None] * self.eb
        gb = grad(col) @ self.eb
        sb = cumulative_trapezoid(np.sqrt(1 + gb**2), self.b, initial=0.0)
        self.sb = sb - sb[j0]
        # along a on every row
        xy = self.anchor + self.b[:, None, None] * self.eb + self.a[None, :, None] * self.ea
        ga = grad(xy) @ self.ea
        sa = cumulative_trapezoid(np.sqrt(1 + ga**2), self.a, axis=1, initial=0.0)
        sa -= sa[:, i0:i0 + 1]
        self.a_of_u = np.stack([np.interp(self.a, row, self.a) for row in sa])  # (nb, na)

    def __call__(self, uv: np.ndarray) -> np.ndarray:
        """(M, 2) pattern offsets, mm → (M, 2) world x, y, mm."""
        uv = np.asarray(uv, float).reshape(-1, 2)
        B = np.interp(uv[:, 1], self.sb, self.b)
        coords = [(B - self.b[0]) / self.h, (uv[:, 0] - self.a[0]) / self.h]
        A = map_coordinates(self.a_of_u, coords, order=1, mode="nearest")
        return self.anchor + A[:, None] * self.ea + B[:, None] * self.eb

    def stretch(self, uv: np.ndarray, grad: _GradientGrid) -> np.ndarray:
        """(M,) max |σ − 1| of the map's Jacobian onto the surface at pattern offsets uv
        (central differences over ± 2 grid steps)."""
        d = 2 * self.h
        tang = []
        for e in (np.array([d, 0.0]), np.array([0.0, d])):
            p1, p0 = self(uv + e), self(uv - e)
            dxy = (p1 - p0) / (2 * d)
            g = grad(0.5 * (p0 + p1))
            tang.append(np.column_stack([dxy, np.einsum("ij,ij->i", g, dxy)]))
        tu, tv = tang
        E, F, G = (tu * tu).sum(1), (tu * tv).sum(1), (tv * tv).sum(1)
        tr, det = E + G, E * G - F * F
        disc = np.sqrt(np.maximum(tr * tr / 4 - det, 0.0))
        s1, s2 = np.sqrt(tr / 2 + disc), np.sqrt(np.maximum(tr / 2 - disc, 0.0))
        return np.maximum(np.abs(s1 - 1), np.abs(s2 - 1))


def _candidate_directions(surf: Surface, anchor: np.ndarray, radius: float) -> list[float]:
    cands = [0.0, np.pi / 2]
    q = surf.quadric(anchor, max(radius, 4 * surf.hole_radius_mm))
    if q is not None:
        H = np.array([[2 * q[3], q[4]], [q[4], 2 * q[5]]])
        w, v = np.linalg.eigh(H)
        big = v[:, int(np.argmax(np.abs(w)))]
        cands.append(float(np.arctan2(big[1], big[0])))
        if np.hypot(q[1], q[2]) > 1e-6:
            cands.append(float(np.arctan2(q[2], q[1])))
    out: list[float] = []
    for t in cands:
        t = float(np.mod(t, np.pi))
        if all(min(abs(t - o), np.pi - abs(t - o)) > np.radians(1.0) for o in out):
            out.append(t)
    return out


def project_wrap(polylines, cloud: PointCloud | np.ndarray | Surface, anchor=None,
                 direction_deg: float | None = None, step_mm: float | None = None,
                 max_stretch_samples: int = 4000) -> Projection:
    """Equal-arc-length projection (see module docstring). ``anchor`` (2,) mm: the point that
    stays put (default: the centre of the polylines' bounding box)."""
    pts, off = _pack(polylines)
    anchor = (0.5 * (pts.min(0) + pts.max(0)) if anchor is None
              else np.asarray(anchor, float).reshape(2))
    surf = cloud if isinstance(cloud, Surface) else surface_for(polylines, cloud, anchor)
    step = float(step_mm or surf.spacing_mm)
    rel = pts - anchor
    radius = float(np.max(np.linalg.norm(rel, axis=1))) if len(rel) else 0.0
    h = max(surf.spacing_mm, 2 * (radius + 1.0) / _MAX_GRID)
    grad = _GradientGrid(surf, anchor, radius + 4 * h, h)
    dense_rel, doff = densify_packed(rel, off, step)
    rng = np.random.default_rng(0)
    probe = dense_rel[rng.choice(len(dense_rel), min(len(dense_rel), max_stretch_samples),
                                 replace=False)]
    thetas = ([np.radians(direction_deg)] if direction_deg is not None
              else _candidate_directions(surf, anchor, radius))
    best = None
    for t in thetas:
        c, s = np.cos(t), np.sin(t)
        uv = rel @ np.array([[c, -s], [s, c]])              # (a, b) components
        m = ArcLengthMap(grad, anchor, t, (uv[:, 0].min(), uv[:, 0].max()),
                         (uv[:, 1].min(), uv[:, 1].max()), h)
        st = float(np.max(m.stretch(probe @ np.array([[c, -s], [s, c]]), grad)))
        if best is None or st < best[0] - 1e-9:
            best = (st, t, m)
    stretch, theta, amap = best
    c, s = np.cos(theta), np.sin(theta)
    xy = amap(dense_rel @ np.array([[c, -s], [s, c]]))
    smp = surf.sample(xy)
    xyz = np.column_stack([xy, smp.z])
    paths, marked, (gap, slope) = _measured(xyz, doff, smp.unmeasured, smp.gap_mm,
                                            smp.slope_deg)
    total = _xy_length(xyz, doff)
    return Projection(paths, "wrap", step, surf.hole_radius_mm, gap, slope, stretch,
                      float(np.degrees(theta)), (float(anchor[0]), float(anchor[1])),
                      path_mm=total, unmarked_mm=total - marked)

