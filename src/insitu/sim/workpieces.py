"""Workpieces of the simulated rig: exact closed triangle meshes and their true top surfaces.

World frame, mm: the table top is z = 0 and parts stand on it; x is the direction scan lines
are offset along, y the direction a line runs. Catalogue parts (:func:`make_workpiece`) are the
test parts of the papers, centred on the origin; any of them can be placed with ``x``, ``y``
(mm) and ``angle_deg`` (about +z). Curved edges and surfaces are tessellated so that the mesh
is within 1 µm of the true shape; ``height_fn`` is the true (analytic) top surface.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from insitu.errors import ConfigError
from insitu.formats.mesh import MESH_SUFFIXES, read_mesh
from insitu.sim import meshes

if TYPE_CHECKING:                       # open3d takes 0.4 s to import: only where it is used
    import open3d as o3d

HeightFn = Callable[[np.ndarray, np.ndarray], np.ndarray]

TOL_MM = 1e-3
"""Tessellation tolerance: chord error of curved edges, interpolation error of surfaces."""



@dataclass(frozen=True, eq=False)
class Workpiece:
    """A rigid part: a closed mesh with outward normals, world frame, mm.

    vertices: (N, 3) float64 mm; triangles: (M, 3) int32, counter-clockwise seen from outside;
    params: what it was built from (JSON-serialisable, includes the placement x, y, angle_deg);
    height_fn: true top surface z(x, y), (...) mm → (...) mm, NaN where the part is not under
    (x, y) — for scoring measurements only, never for measuring. The arrays are read-only
    (copy them for ``open3d.utility.Vector3dVector``, which refuses read-only arrays).
    """

    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    params: dict
    height_fn: HeightFn | None = None

    def __post_init__(self) -> None:
        v = np.array(self.vertices, np.float64)
        t = np.array(self.triangles, np.int32)
        if v.ndim != 2 or v.shape[1] != 3 or t.ndim != 2 or t.shape[1] != 3:
            raise ValueError("Workpiece: vertices must be (N, 3) and triangles (M, 3)")
        v.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "triangles", t)

    def o3d_tensor_mesh(self) -> o3d.t.geometry.TriangleMesh:
        """The mesh for ``RaycastingScene.add_triangles``: float32 positions, int32 indices."""
        import open3d as o3d

        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(self.vertices.astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(np.ascontiguousarray(self.triangles))
        return mesh

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box: (3,) min and (3,) max corner, mm."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def height(self, x, y) -> np.ndarray:
        """True top-surface z at world (x, y), broadcast arrays, mm; NaN off the part."""
        if self.height_fn is None:
            raise ValueError(f"workpiece {self.name!r} has no true height function")
        x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        return np.asarray(self.height_fn(x, y), np.float64)


# ---------------------------------------------------------------- catalogue builders
# Each builder: params → (vertices (N, 3), triangles (M, 3), height in the part's own frame).
# Convention: "width" is the extent along x, "length" along y.

def _box(width: float, length: float, z0: float, z1: float):
    hx, hy = width / 2, length / 2
    v, t = meshes.heightfield_block([-hx, hx], [-hy, hy], np.full((2, 2), z1), z0)

    def height(u, w):
        return np.where((np.abs(u) <= hx) & (np.abs(w) <= hy), z1, np.nan)
    return v, t, height


def _step_block(p: dict):
    """Li et al.'s step block: steps of equal length along y, lowest at −y, vertical walls."""
    length, width, hs = p["length"], p["width"], np.array(p["heights"], float)
    n, hy = len(hs), length / 2
    ys = -hy + length * np.arange(n + 1) / n
    prof = [(-hy, 0.0), (hy, 0.0), (hy, hs[-1])]            # (y, z), counter-clockwise
    for k in range(n - 1, 0, -1):
        if hs[k] != hs[k - 1]:
            prof += [(ys[k], hs[k]), (ys[k], hs[k - 1])]
    prof.append((-hy, hs[0]))
    prof = np.array(prof)
    v, t = meshes.prism([prof], meshes.earclip(prof), -width / 2, width / 2, axis="x")

    def height(u, w):
        k = np.clip(np.floor((w + hy) / (length / n)).astype(int), 0, n - 1)
        return np.where((np.abs(u) <= width / 2) & (np.abs(w) <= hy), hs[k], np.nan)
    return v, t, height


def _arc(p: dict):
    """Block with a cylindrical top (axis along y): ``height`` at x = 0, ``height − sagitta``
    at x = ±width/2; radius = ((width/2)² + sagitta²) / (2·sagitta)."""
    w, length, h, sag = p["width"], p["length"], p["height"], p["sagitta"]
    if sag >= h or sag > w / 2:
        raise ConfigError(f"workpiece 'arc': sagitta {sag:g} mm must be < height {h:g} mm "
                          f"and ≤ width/2 {w / 2:g} mm")
    radius = ((w / 2) ** 2 + sag ** 2) / (2 * sag)
    zc, half = h - radius, np.arcsin(w / 2 / radius)
    # chord error ≤ TOL·cos(steepest slope): the vertical error stays below TOL too
    n = meshes.segments_for_arc(radius, 2 * half, TOL_MM * np.cos(half), multiple=2)
    phi = np.linspace(-half, half, n + 1)
    xs, top = radius * np.sin(phi), zc + radius * np.cos(phi)
    xs[[0, n // 2, n]] = -w / 2, 0.0, w / 2                 # exact ends and apex
    top[[0, n // 2, n]] = h - sag, h, h - sag
    v, t = meshes.heightfield_block(xs, [-length / 2, length / 2],
                                    np.repeat(top[:, None], 2, 1), 0.0)

    def height(u, y):
        inside = (np.abs(u) <= w / 2) & (np.abs(y) <= length / 2)
        return np.where(inside, zc + np.sqrt(np.maximum(radius ** 2 - u ** 2, 0.0)), np.nan)
    return v, t, height


def _insert(p: dict):
    """Triangular turning insert: equilateral triangle of side ``side`` (sharp corners), each
    corner rounded with ``nose_radius`` (the sides stay tangent to the sharp triangle's sides),
    ``thickness`` thick, round through-hole ``hole_diameter`` at the centroid (origin). The
    side at x = −side/(2√3) is parallel to y; the opposite corner points to +x."""
    s, r, th, rh = p["side"], p["nose_radius"], p["thickness"], p["hole_diameter"] / 2
    r_in, r_c = s / (2 * np.sqrt(3)), s / np.sqrt(3)
    if not (0 < r < r_in / 2 and rh < r_in - 0.05):
        raise ConfigError("workpiece 'insert': need 0 < nose_radius < inscribed radius/2 and "
                          "hole radius < inscribed radius − 0.05 mm")
    sharp = np.array([[-r_in, -s / 2], [r_c, 0.0], [-r_in, s / 2]])   # counter-clockwise
    centres = sharp * (1 - 2 * r / r_c)                     # nose centres, 2r from the corner
    k_nose = meshes.segments_for_arc(r, 2 * np.pi / 3, TOL_MM, multiple=4)
    k_hole = meshes.segments_for_arc(rh, 2 * np.pi, TOL_MM, multiple=4)
    n_side = int(np.ceil(k_hole / 3))
    outer = []
    for i in range(3):
        a_in = np.arctan2(*(sharp[i] - sharp[i - 1])[::-1]) - np.pi / 2      # side normals
        arc = a_in + np.linspace(0, 2 * np.pi / 3, k_nose + 1)
        pts = centres[i] + r * np.column_stack([np.cos(arc), np.sin(arc)])
        nxt = centres[(i + 1) % 3] + r * np.array([np.cos(arc[-1]), np.sin(arc[-1])])
        side = pts[-1] + np.linspace(0, 1, n_side + 1)[1:-1, None] * (nxt - pts[-1])
        outer += [pts, side]
    outer = np.vstack(outer)
    outer[np.isclose(outer[:, 0], -r_in, rtol=0, atol=1e-12), 0] = -r_in    # exact flat side
    a_hole = 2 * np.pi * np.arange(k_hole) / k_hole
    hole = rh * np.column_stack([np.cos(a_hole), np.sin(a_hole)])
    cap = meshes.zipper(outer, hole)
    n = len(outer)
    cap = np.where(cap >= n, n + k_hole - 1 - (cap - n), cap)   # hole loop stored clockwise
    v, t = meshes.prism([outer, hole[::-1]], cap, 0.0, th, axis="z")

    def height(u, w):
        q = np.stack([u, w], -1)
        d = np.full(np.shape(u), np.inf)
        inside = np.ones(np.shape(u), bool)
        for i in range(3):                       # distance to the triangle of nose centres
            a, b = centres[i], centres[(i + 1) % 3]
            e = b - a
            inside &= (e[0] * (q[..., 1] - a[1]) - e[1] * (q[..., 0] - a[0])) >= 0
            f = np.clip(((q - a) @ e) / (e @ e), 0, 1)
            d = np.minimum(d, np.linalg.norm(q - a - f[..., None] * e, axis=-1))
        solid = (inside | (d <= r)) & (u ** 2 + w ** 2 >= rh ** 2)
        return np.where(solid, th, np.nan)
    return v, t, height


def _tilted_plane(p: dict):
    """Plate whose top is tilted ``tilt_deg`` about y, rising towards +x, ``top_z`` at x = 0.

    ``width`` × ``length`` is the top face measured in its own plane. The default (60 mm,
    15°, 8 mm) leaves the low edge only 0.24 mm above the table, so a 5 mm plate cannot stand
    there on its own: the part is the plate merged with its wedge support — the solid between
    the table and the tilted top, cut by vertical walls at the top's edges.
    """
    w, length, tilt, top_z = p["width"], p["length"], np.radians(p["tilt_deg"]), p["top_z"]
    hx, slope = w / 2 * np.cos(tilt), np.tan(tilt)
    if top_z - hx * abs(slope) <= 0:
        raise ConfigError("workpiece 'tilted-plane': the tilted top reaches the table")
    xs = np.array([-hx, hx])
    v, t = meshes.heightfield_block(xs, [-length / 2, length / 2],
                                    np.repeat((top_z + xs * slope)[:, None], 2, 1), 0.0)

    def height(u, y):
        return np.where((np.abs(u) <= hx) & (np.abs(y) <= length / 2), top_z + u * slope, np.nan)
    return v, t, height


def _freeform_fn(p: dict) -> HeightFn:
    def f(x, y):
        wave = (np.sin(2 * np.pi * x / p["wavelength_x"])
                * np.cos(2 * np.pi * y / p["wavelength_y"]))
        r2 = (x - p["bump_x"]) ** 2 + (y - p["bump_y"]) ** 2
        return p["base"] + p["amp"] * wave + p["bump"] * np.exp(-r2 / (2 * p["bump_sigma"] ** 2))
    return f


def _freeform(p: dict):
    """Block with z = base + amp·sin(2πx/λx)·cos(2πy/λy) + bump·exp(−|(x, y) − c|²/(2σ²)).

    Grid spacing h from the interpolation bound |e| ≤ M·h²/4 on right triangles (M: largest
    Hessian eigenvalue magnitude, estimated on a 0.5 mm grid with a 1.25 safety factor).
    """
    f, w, length = _freeform_fn(p), p["width"], p["length"]
    gx, gy = np.meshgrid(np.linspace(-w / 2, w / 2, int(w / 0.5) + 1),
                         np.linspace(-length / 2, length / 2, int(length / 0.5) + 1))
    d = 1e-2
    fxx = (f(gx + d, gy) - 2 * f(gx, gy) + f(gx - d, gy)) / d ** 2
    fyy = (f(gx, gy + d) - 2 * f(gx, gy) + f(gx, gy - d)) / d ** 2
    fxy = (f(gx + d, gy + d) - f(gx + d, gy - d) - f(gx - d, gy + d)
           + f(gx - d, gy - d)) / (4 * d * d)
    m = 1.25 * np.max(np.abs(fxx + fyy) / 2 + np.hypot((fxx - fyy) / 2, fxy)) + 1e-9
    h = np.sqrt(4 * TOL_MM / m)
    xs = np.linspace(-w / 2, w / 2, int(np.ceil(w / h)) + 1)
    ys = np.linspace(-length / 2, length / 2, int(np.ceil(length / h)) + 1)
    top = f(*np.meshgrid(xs, ys, indexing="ij"))
    if top.min() <= 0:
        raise ConfigError("workpiece 'freeform': the surface reaches the table")
    v, t = meshes.heightfield_block(xs, ys, top, 0.0)

    def height(u, y):
        return np.where((np.abs(u) <= w / 2) & (np.abs(y) <= length / 2), f(u, y), np.nan)
    return v, t, height


def _plate(p: dict):
    """Flat calibration plate, top at ``top_z``."""
    return _box(p["width"], p["length"], p["top_z"] - p["thickness"], p["top_z"])


_CATALOGUE: dict[str, tuple[Callable, dict]] = {
    "step-block": (_step_block, {"length": 80.0, "width": 20.0,
                                 "heights": [3.0, 5.0, 10.0, 15.0]}),
    "arc": (_arc, {"width": 40.0, "length": 40.0, "height": 11.5, "sagitta": 5.0}),
    "insert": (_insert, {"side": 16.14, "nose_radius": 0.2, "thickness": 4.68,
                         "hole_diameter": 3.80}),
    "tilted-plane": (_tilted_plane, {"width": 60.0, "length": 60.0, "tilt_deg": 15.0,
                                     "top_z": 8.0}),
    "freeform": (_freeform, {"width": 60.0, "length": 60.0, "base": 6.0, "amp": 2.5,
                             "wavelength_x": 50.0, "wavelength_y": 60.0, "bump": 2.0,
                             "bump_x": 8.0, "bump_y": -6.0, "bump_sigma": 9.0}),
    "blank-stainless": (_plate, {"width": 40.0, "length": 40.0, "thickness": 5.0, "top_z": 5.0}),
    "blank-anodised": (_plate, {"width": 40.0, "length": 40.0, "thickness": 5.0, "top_z": 5.0}),
    "blank-beech": (_plate, {"width": 40.0, "length": 40.0, "thickness": 8.0, "top_z": 8.0}),
    "plate": (_plate, {"width": 260.0, "length": 260.0, "thickness": 10.0, "top_z": 0.0}),
    "table": (_plate, {"width": 400.0, "length": 400.0, "thickness": 20.0, "top_z": 0.0}),
}
WORKPIECES: tuple[str, ...] = tuple(_CATALOGUE)
_POSITIVE = ("length", "width", "height", "sagitta", "side", "nose_radius", "thickness",
             "hole_diameter", "wavelength_x", "wavelength_y", "bump_sigma")
PLACEMENT = ("x", "y", "angle_deg")


def _placed(name: str, v: np.ndarray, t: np.ndarray, height: HeightFn | None,
            params: dict) -> Workpiece:
    px, py, ang = params["x"], params["y"], params["angle_deg"]

    def world_height(x, y):
        return height(*meshes.unplace(x, y, px, py, ang))
    return Workpiece(name, meshes.place(v, px, py, ang), t, params,
                     None if height is None else world_height)


def make_workpiece(name: str, **overrides) -> Workpiece:
    """Catalogue part ``name`` (one of :data:`WORKPIECES`), defaults overridden by keyword.

    Dimensions in mm, angles in degrees. Placement: ``x``, ``y`` (shift, mm) and ``angle_deg``
    (rotation about +z through the part's origin, applied first). Raises ConfigError for an
    unknown name or a shape that cannot be built, TypeError for an unknown parameter.
    """
    if name not in _CATALOGUE:
        raise ConfigError(f"workpiece {name!r}: expected one of {', '.join(WORKPIECES)} "
                          "or a mesh file (STL/PLY/OBJ)")
    build, defaults = _CATALOGUE[name]
    unknown = set(overrides) - set(defaults) - set(PLACEMENT)
    if unknown:
        raise TypeError(f"make_workpiece({name!r}): unknown parameter(s) {sorted(unknown)}; "
                        f"expected {sorted(defaults) + list(PLACEMENT)}")
    params = {**defaults, **{k: 0.0 for k in PLACEMENT}, **overrides}
    for key, val in params.items():
        params[key] = [float(h) for h in val] if key == "heights" else float(val)
        vals = np.atleast_1d(params[key])
        positive = key in _POSITIVE or key == "heights"
        if vals.size == 0 or not np.all(np.isfinite(vals)) or (positive and not np.all(vals > 0)):
            raise ConfigError(f"workpiece {name!r}: {key} = {val!r} must be finite"
                              + (" and > 0" if positive else ""))
    v, t, height = build(params)
    return _placed(name, v, t, height, params)


def _raycast_height(vertices: np.ndarray, triangles: np.ndarray) -> HeightFn:
    """z of the first surface hit by a vertical ray from above (float32 ray casting)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)),
                        o3d.core.Tensor(triangles.astype(np.uint32)))
    z0 = float(np.float32(vertices[:, 2].max() + 1.0))

    def height(x, y):
        x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        rays = np.zeros((x.size, 6), np.float32)
        rays[:, 0], rays[:, 1], rays[:, 2], rays[:, 5] = x.ravel(), y.ravel(), z0, -1.0
        t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
        return np.where(np.isfinite(t), z0 - t, np.nan).reshape(x.shape)
    return height


Pose = tuple[float, float, float]
"""Where a part lies on the table: x, y (mm) of its own frame's origin and its turn about +z,
degrees."""


def random_pose(rng: np.random.Generator, half_mm: float = 25.0) -> Pose:
    """A pose drawn uniformly: x, y within ±``half_mm`` mm, any turn (−180 … 180°)."""
    x, y = rng.uniform(-half_mm, half_mm, 2)
    return float(x), float(y), float(rng.uniform(-180.0, 180.0))


def to_part(part: Workpiece, x, y) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) mm → the placed part's own frame."""
    p = part.params
    return meshes.unplace(x, y, p.get("x", 0.0), p.get("y", 0.0), p.get("angle_deg", 0.0))


def to_world(part: Workpiece, u, v) -> tuple[np.ndarray, np.ndarray]:
    """The placed part's own frame (u, v) mm → world (x, y)."""
    a = np.radians(part.params.get("angle_deg", 0.0))
    u, v = np.asarray(u, float), np.asarray(v, float)
    return (part.params.get("x", 0.0) + np.cos(a) * u - np.sin(a) * v,
            part.params.get("y", 0.0) + np.sin(a) * u + np.cos(a) * v)


def part_matrix(part: Workpiece) -> np.ndarray:
    """(4, 4) ``T_world_part`` of a placed part: its own frame's points → world, mm."""
    a = np.radians(part.params.get("angle_deg", 0.0))
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:2, 3] = part.params.get("x", 0.0), part.params.get("y", 0.0)
    return T


def workpiece_at(name: str, pose: Pose = (0.0, 0.0, 0.0)) -> Workpiece:
    """Catalogue part or mesh file ``name`` placed at ``pose`` (see :data:`Pose`)."""
    x, y, angle = pose
    if Path(name).suffix.lower() in MESH_SUFFIXES:
        return load_mesh_workpiece(name, x, y, angle)
    return make_workpiece(name, x=x, y=y, angle_deg=angle)


def load_mesh_workpiece(path: str | Path, x: float = 0.0, y: float = 0.0,
                        angle_deg: float = 0.0) -> Workpiece:
    """A part from an STL, PLY or OBJ mesh in mm, world frame, placed like the catalogue.

    ``height_fn`` ray-casts the mesh straight down (NaN off the part). Raises FormatError when
    the file is missing, unreadable or has no triangles.
    """
    path = Path(path)
    v, t = read_mesh(path)
    v = meshes.place(v, x, y, angle_deg)
    params = {"path": str(path), "x": float(x), "y": float(y), "angle_deg": float(angle_deg)}
    return Workpiece(path.stem, v, t.astype(np.int32), params, _raycast_height(v, t))
