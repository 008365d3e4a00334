"""Catalogue workpieces: closed outward meshes, exact dimensions, true heights = the mesh."""

import json

import numpy as np
import open3d as o3d
import pytest
from scipy.optimize import minimize

from insitu.errors import ConfigError, FormatError
from insitu.sim import meshes
from insitu.sim.workpieces import WORKPIECES, load_mesh_workpiece, make_workpiece

S3 = np.sqrt(3.0)
T15 = np.radians(15.0)
EXACT_BOUNDS = {
    "step-block": ([-10, -40, 0], [10, 40, 15]),
    "arc": ([-20, -20, 0], [20, 20, 11.5]),
    "insert": ([-16.14 / (2 * S3), -(8.07 - (S3 - 1) * 0.2), 0],
               [16.14 / S3 - 0.2, 8.07 - (S3 - 1) * 0.2, 4.68]),
    "tilted-plane": ([-30 * np.cos(T15), -30, 0], [30 * np.cos(T15), 30, 8 + 30 * np.sin(T15)]),
    "freeform": ([-30, -30, 0], [30, 30, None]),          # top: the surface's maximum
    "blank-stainless": ([-20, -20, 0], [20, 20, 5]),
    "blank-anodised": ([-20, -20, 0], [20, 20, 5]),
    "blank-beech": ([-20, -20, 0], [20, 20, 8]),
    "plate": ([-130, -130, -10], [130, 130, 0]),
    "table": ([-200, -200, -20], [200, 200, 0]),
}
PLACED = [(name, {}) for name in WORKPIECES] + [
    ("insert", {"x": 12.0, "y": -7.0, "angle_deg": 33.0}),
    ("arc", {"x": -20.0, "y": 10.0, "angle_deg": -120.0}),
    ("step-block", {"x": 30.0, "y": -5.0, "angle_deg": 90.0}),
]


def _legacy(part) -> o3d.geometry.TriangleMesh:
    # Open3D's Vector3dVector refuses read-only arrays: copy
    return o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(part.vertices)),
                                     o3d.utility.Vector3iVector(np.array(part.triangles)))


def _cast_down(part, x, y):
    """(N,) z of the first hit of a vertical ray onto the part's mesh, NaN on a miss."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(part.o3d_tensor_mesh())
    z0 = float(np.float32(part.bounds()[1][2] + 1.0))
    rays = np.zeros((len(x), 6), np.float32)
    rays[:, 0], rays[:, 1], rays[:, 2], rays[:, 5] = x, y, z0, -1.0
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(float)
    return np.where(np.isfinite(t), z0 - t, np.nan)


def _clear_samples(part, rng, n_in=2000, n_out=300, eps=5e-3):
    """Random (x, y) in and around the part, at least ``eps`` mm from any edge or wall of the
    true top surface (there the tessellation and the true shape may differ by up to 1 µm)."""
    lo, hi = part.bounds()
    pad = 0.1 * (hi[:2] - lo[:2])
    xs, ys, excluded, total = [], [], 0, 0
    n_inside = n_outside = 0
    while n_inside < n_in or n_outside < n_out:
        x = rng.uniform(lo[0] - pad[0], hi[0] + pad[0], 4000)
        y = rng.uniform(lo[1] - pad[1], hi[1] + pad[1], 4000)
        h = part.height(x, y)
        nb = np.stack([part.height(x + dx, y + dy)
                       for dx, dy in ((eps, 0), (-eps, 0), (0, eps), (0, -eps))])
        same = np.all(np.isnan(nb) == np.isnan(h), axis=0)
        smooth = np.all(np.isnan(nb) | (np.abs(nb - h) < 0.05), axis=0)
        ok = same & smooth
        total += len(x)
        excluded += int((~ok).sum())
        xs.append(x[ok])
        ys.append(y[ok])
        n_inside += int((ok & np.isfinite(h)).sum())
        n_outside += int((ok & np.isnan(h)).sum())
    assert excluded < 0.01 * total                          # edges are rare, not everywhere
    return np.concatenate(xs), np.concatenate(ys)


@pytest.mark.parametrize("name", WORKPIECES)
def test_mesh_is_closed_outward_and_without_degenerate_triangles(name):
    part = make_workpiece(name)
    v, t = part.vertices, part.triangles
    mesh = _legacy(part)
    assert mesh.is_orientable()
    assert mesh.is_edge_manifold(allow_boundary_edges=False) and mesh.is_vertex_manifold()
    if name != "freeform":             # is_watertight also tests self-intersection, in O(M²)
        assert mesh.is_watertight()
    # every directed edge once, and its reverse once: closed and consistently oriented
    e = t[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    key, rev = e[:, 0] * len(v) + e[:, 1], e[:, 1] * len(v) + e[:, 0]
    assert len(np.unique(key)) == len(key) and np.all(np.isin(rev, key))
    # outward: positive enclosed volume
    vol = np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6
    assert vol > 0
    area = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
    assert area.min() > 1e-3
    assert len(np.unique(v, axis=0)) == len(v)
    assert v.dtype == np.float64 and t.dtype == np.int32
    json.dumps(part.params)


def _self_intersecting(vertices, triangles, cells=16) -> bool:
    """Open3D's self-intersection test (O(M²) over M triangles) run in each cell of a
    ``cells`` × ``cells`` grid over x, y on the triangles whose boxes reach into it: two
    triangles that cross share a point, which lies in a cell both reach. Each cell's mesh keeps
    its triangles' shared vertices shared (Open3D skips pairs that share a vertex)."""
    v, t = np.array(vertices, float), np.array(triangles)
    lo, hi = v[t].min(1)[:, :2], v[t].max(1)[:, :2]
    edges = [np.linspace(a, b, cells + 1) for a, b in zip(v[:, :2].min(0), v[:, :2].max(0))]
    for x0, x1 in zip(edges[0][:-1], edges[0][1:]):
        for y0, y1 in zip(edges[1][:-1], edges[1][1:]):
            near = (lo[:, 0] <= x1) & (hi[:, 0] >= x0) & (lo[:, 1] <= y1) & (hi[:, 1] >= y0)
            used, local = np.unique(t[near], return_inverse=True)
            mesh = o3d.geometry.TriangleMesh(
                o3d.utility.Vector3dVector(v[used]),
                o3d.utility.Vector3iVector(local.reshape(-1, 3).astype(np.int32)))
            if mesh.is_self_intersecting():
                return True
    return False


def test_freeform_is_watertight():
    """Open3D's watertight test on the freeform's 137k triangles, its O(M²) self-intersection
    part cell by cell (_self_intersecting)."""
    part = make_workpiece("freeform")
    mesh = _legacy(part)
    assert mesh.is_edge_manifold(allow_boundary_edges=False) and mesh.is_vertex_manifold()
    assert not _self_intersecting(part.vertices, part.triangles)


@pytest.mark.parametrize("name", ["step-block", "insert"])
def test_the_cell_by_cell_self_intersection_test_agrees_with_open3d(name):
    """On whole meshes small enough for Open3D's own test: the same answer, intact and with
    one top vertex pushed through the part's bottom."""
    part = make_workpiece(name)
    v, t = np.array(part.vertices), np.array(part.triangles)
    dented = v.copy()
    k = int(np.argmax(v[:, 2]))
    dented[k, 2] = v[:, 2].min() - 1.0
    for verts, crossing in ((v, False), (dented, True)):
        whole = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(verts),
                                          o3d.utility.Vector3iVector(t))
        assert whole.is_self_intersecting() == crossing
        assert _self_intersecting(verts, t, cells=4) == crossing


@pytest.mark.parametrize("name", WORKPIECES)
def test_bounding_box_is_exact(name):
    lo, hi = make_workpiece(name).bounds()
    want_lo, want_hi = EXACT_BOUNDS[name]
    if name == "freeform":
        part = make_workpiece(name)
        g = np.linspace(-30, 30, 601)
        gx, gy = np.meshgrid(g, g)
        h = part.height(gx, gy)
        k = np.argmax(h)
        res = minimize(lambda p: -part.height(p[0], p[1]), [gx.flat[k], gy.flat[k]],
                       method="Nelder-Mead", options={"xatol": 1e-9, "fatol": 1e-12})
        assert -1e-3 < -res.fun - hi[2] < 1e-3             # vertex at most 1 µm below the peak
        want_hi = [30, 30, hi[2]]
    np.testing.assert_allclose(lo, want_lo, rtol=0, atol=1e-9)
    np.testing.assert_allclose(hi, want_hi, rtol=0, atol=1e-9)


@pytest.mark.parametrize(("name", "placement"), PLACED,
                         ids=[f"{n}{'-placed' if p else ''}" for n, p in PLACED])
def test_true_height_matches_a_vertical_ray_cast_onto_the_mesh(name, placement):
    part = make_workpiece(name, **placement)
    x, y = _clear_samples(part, np.random.default_rng(7))
    h = part.height(x, y)
    z = _cast_down(part, x, y)
    inside = np.isfinite(h)
    assert inside.sum() >= 2000 and (~inside).sum() >= 300
    np.testing.assert_array_equal(np.isfinite(z), inside)  # NaN exactly where the ray misses
    assert np.max(np.abs(z[inside] - h[inside])) < 2e-3


def test_the_insert_hole_goes_through():
    part = make_workpiece("insert")
    x = np.array([0.0, 0.0, 1.85, 1.95, -4.6])
    y = np.array([0.0, 1.85, 0.0, 0.0, 0.0])
    z = _cast_down(part, x, y)
    assert np.isnan(z[:3]).all() and np.isnan(part.height(x[:3], y[:3])).all()
    np.testing.assert_allclose(z[3:], 4.68, atol=1e-5)
    # the placed insert's hole moves with it
    moved = make_workpiece("insert", x=12.0, y=-7.0, angle_deg=33.0)
    assert np.isnan(_cast_down(moved, np.array([12.0]), np.array([-7.0])))[0]
    assert np.isnan(moved.height(12.0, -7.0))


def test_step_heights_are_exact():
    part = make_workpiece("step-block")
    y = np.array([-30.0, -10.0, 10.0, 30.0])
    np.testing.assert_array_equal(part.height(np.zeros(4), y), [3, 5, 10, 15])
    np.testing.assert_allclose(_cast_down(part, np.full(4, 3.3), y), [3, 5, 10, 15], atol=1e-5)
    assert set(np.unique(part.vertices[:, 2])) == {0, 3, 5, 10, 15}
    assert set(np.unique(part.vertices[:, 1])) == {-40, -20, 0, 20, 40}
    two = make_workpiece("step-block", heights=(2, 4))
    np.testing.assert_array_equal(two.height([0, 0], [-20, 20]), [2, 4])
    assert two.params["heights"] == [2.0, 4.0]


def test_placement_moves_bounds_and_height_together():
    base = make_workpiece("step-block")
    part = make_workpiece("step-block", x=30.0, y=-5.0, angle_deg=90.0)
    lo, hi = part.bounds()
    np.testing.assert_allclose(lo, [-10, -15, 0], atol=1e-9)
    np.testing.assert_allclose(hi, [70, 5, 15], atol=1e-9)
    # local (0, −30) (3 mm step) → world (60, −5); local (0, 30) (15 mm) → world (0, −5)
    np.testing.assert_array_equal(part.height([60.0, 0.0], [-5.0, -5.0]), [3, 15])
    assert np.isnan(part.height(0.0, 30.0)) and base.height(0.0, 30.0) == 15
    rng = np.random.default_rng(3)
    u, v = rng.uniform(-12, 12, 500), rng.uniform(-42, 42, 500)
    c, s = 0.0, 1.0
    np.testing.assert_array_equal(part.height(30 + c * u - s * v, -5 + s * u + c * v),
                                  base.height(u, v))
    assert part.params["x"] == 30.0 and part.params["angle_deg"] == 90.0


def test_overrides_and_bad_parameters():
    plate = make_workpiece("plate", top_z=5.0)
    lo, hi = plate.bounds()
    assert lo[2] == -5.0 and hi[2] == 5.0 and plate.height(100.0, -100.0) == 5.0
    assert np.isnan(plate.height(131.0, 0.0))
    assert make_workpiece("table").bounds()[1][2] == 0.0
    with pytest.raises(ConfigError, match="expected one of"):
        make_workpiece("teapot")
    with pytest.raises(TypeError, match="unknown parameter"):
        make_workpiece("arc", radius=3.0)
    with pytest.raises(ConfigError, match="width"):
        make_workpiece("plate", width=-1.0)
    with pytest.raises(ConfigError, match="sagitta"):
        make_workpiece("arc", sagitta=12.0)


def test_tessellation_tolerances():
    assert meshes.segments_for_arc(42.5, 2 * np.arcsin(20 / 42.5), 1e-3) == 72
    assert meshes.segments_for_arc(0.2, 2 * np.pi / 3, 1e-3, multiple=4) == 12
    arc = make_workpiece("arc")
    top = arc.vertices[arc.vertices[:, 2] > 0]
    x = np.unique(top[:, 0])
    z = arc.height(x, np.zeros_like(x))
    np.testing.assert_allclose(np.hypot(x, z - (11.5 - 42.5)), 42.5, rtol=0, atol=1e-12)
    mid = np.column_stack([x[1:] + x[:-1], z[1:] + z[:-1]]) / 2
    sagitta = 42.5 - np.hypot(mid[:, 0], mid[:, 1] - (11.5 - 42.5))
    assert sagitta.max() < 1e-3                             # chord error below 1 µm
    xf = np.linspace(-20, 20, 200001)                       # and the height error too
    zf = np.interp(xf, x, z)
    assert np.max(arc.height(xf, np.zeros_like(xf)) - zf) < 1e-3


@pytest.mark.parametrize(("suffix", "tol"), [(".stl", 2e-5), (".ply", 2e-5), (".obj", 1e-4)])
def test_load_mesh_workpiece_round_trip(tmp_path, suffix, tol):
    """STL and PLY keep float32 vertices; Open3D writes OBJ with 6 significant digits."""
    part = make_workpiece("insert", x=5.0, y=-3.0, angle_deg=20.0)
    mesh = _legacy(part)
    mesh.compute_triangle_normals()
    path = tmp_path / f"insert{suffix}"
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    back = load_mesh_workpiece(path)
    assert back.name == "insert" and back.params["path"] == str(path)
    assert len(back.triangles) == len(part.triangles)
    assert _legacy(back).is_watertight()
    for a, b in zip(back.bounds(), part.bounds()):
        np.testing.assert_allclose(a, b, atol=tol)
    x, y = _clear_samples(part, np.random.default_rng(1), n_in=500, n_out=100, eps=100 * tol)
    h, hb = part.height(x, y), back.height(x, y)
    np.testing.assert_array_equal(np.isfinite(hb), np.isfinite(h))
    assert np.nanmax(np.abs(hb - h)) < 2e-3
    assert np.isnan(back.height(5.0, -3.0))                 # the hole
    shifted = load_mesh_workpiece(path, x=10.0)
    np.testing.assert_allclose(shifted.bounds()[0], back.bounds()[0] + [10, 0, 0], atol=1e-9)


def test_load_mesh_workpiece_errors(tmp_path):
    missing = tmp_path / "nothere.stl"
    with pytest.raises(FormatError, match="nothere.stl: no such mesh file"):
        load_mesh_workpiece(missing)
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(np.random.default_rng(0).bytes(3000))
    with pytest.raises(FormatError, match="garbage.stl: no triangles") as err:
        load_mesh_workpiece(garbage)
    assert "\n" not in str(err.value)
    text = tmp_path / "notes.ply"
    text.write_text("not a mesh\n")
    with pytest.raises(FormatError, match="notes.ply"):
        load_mesh_workpiece(text)
    other = tmp_path / "part.step"
    other.write_text("ISO-10303-21;\n")
    with pytest.raises(FormatError, match="part.step: unsupported mesh format"):
        load_mesh_workpiece(other)
