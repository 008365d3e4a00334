"""The edge step of locating (:mod:`insitu.locate.edge_align`): one inset along the lines,
whatever angle they cross the edges at; the edges' normals at any angle; samples beyond their
edge measured so (negative); lines cut short weigh nothing; each line's points taken in the
order of their pixels."""

import numpy as np
import pytest
from test_locate import synthetic_scan

from insitu.geometry.camera import CameraModel
from insitu.geometry.pose import apply, inverse, rot_z
from insitu.locate.edge_align import align_edges, edge_distance, edge_samples
from insitu.locate.reference import reference_from_mesh
from insitu.sim.workpieces import make_workpiece

TRUTH = (12.0, -7.0, 33.0)


@pytest.fixture(scope="module")
def block():
    """(reference heights, edge samples in the part frame: points, dirs; each sample's
    edge normal and cosine to its line)."""
    w = make_workpiece("step-block")
    ref = reference_from_mesh(w.vertices, w.triangles, "step-block")
    pts, lines = synthetic_scan("step-block", TRUTH, noise=0.002)
    found = edge_samples(pts, lines, pts[:, 2] < 0.5)
    pose = inverse((np.radians(TRUTH[2]), np.array([TRUTH[0], TRUTH[1], 0.0])))
    e, u = apply(pose, found.points), found.dirs @ rot_z(pose[0])[:2, :2].T
    s, n = edge_distance(ref.heights, e, u)
    keep = np.isfinite(s)
    nu = np.einsum("ij,ij->i", n[keep], u[keep])
    return ref.heights, e[keep], u[keep], nu


@pytest.mark.parametrize("inset", [0.04, -0.04])
def test_one_inset_along_the_lines_leaves_the_pose(block, inset):
    """Every sample moved further inside (or beyond) its edge by 0.04 mm along its line —
    0.04·cos across it, the line crossing the long sides at 33° and the steps at 57°, as a
    line's end found pixel by pixel loses the same length whatever the angle: the pose moves
    by less than 0.002 mm and 0.002°, the inset by the 0.04 mm (one inset across the edges
    moves the part 0.005 mm towards the steps)."""
    heights, e, u, nu = block
    assert nu.min() < 0.6 < nu.max()                 # both kinds of crossing are there
    moved = e.copy()
    moved[:, :2] -= inset * u
    before, fit = align_edges(heights, e, u), align_edges(heights, moved, u)
    assert abs(np.degrees(fit.angle_rad - before.angle_rad)) < 0.002
    assert np.linalg.norm(fit.shift_mm - before.shift_mm) < 0.002, fit.shift_mm
    assert fit.b_mm - before.b_mm == pytest.approx(inset, abs=0.002)
    assert fit.samples > 0.95 * len(e)


def test_a_sample_beyond_its_edge_measures_negative():
    """The distance to the edge along the line is signed: 0.05 mm short of a step's edge
    is +0.05, 0.05 mm beyond it −0.05 (a line's end blurred past it), not cut to 0."""
    w = make_workpiece("step-block")
    ref = reference_from_mesh(w.vertices, w.triangles, "step-block")
    x_edge = 10.0                                    # the block's side, x = width / 2
    e = np.array([[x_edge - 0.05, 35.0, 15.0], [x_edge + 0.05, 35.0, 15.0]])
    s, _ = edge_distance(ref.heights, e, np.array([[1.0, 0.0], [1.0, 0.0]]))
    assert s == pytest.approx([0.05, -0.05], abs=0.01)


def test_lines_cut_short_weigh_nothing(block):
    """Every sample up to 0.15 mm inside its edge along its line (sampling), and a fifth of
    them, all on one side, 0.5 mm further in (their lines lost their end to the lower line
    in the same pixel columns): those weigh nothing — the pose is the one without them
    within 0.006° and 0.006 mm (Huber weights alone: 0.05 mm off)."""
    heights, e, u, _ = block
    rng = np.random.default_rng(3)
    moved = e.copy()
    moved[:, :2] -= rng.uniform(0, 0.15, len(e))[:, None] * u
    far = np.flatnonzero(e[:, 0] > np.percentile(e[:, 0], 70))
    cut = rng.choice(far, len(e) // 5, replace=False)
    kept = np.setdiff1d(np.arange(len(e)), cut)
    clean = align_edges(heights, moved[kept], u[kept])
    moved[cut, :2] -= 0.5 * u[cut]
    fit = align_edges(heights, moved, u)
    assert abs(np.degrees(fit.angle_rad - clean.angle_rad)) < 0.006
    assert np.linalg.norm(fit.shift_mm - clean.shift_mm) < 0.006, fit.shift_mm


def test_a_lines_points_are_taken_in_the_order_of_their_pixels():
    """A line seen from the side: a top (z = 5) in the columns from 320 on, the floor
    before them. In x, y the floor's points run on under the top's (as the lower line
    beside an oblique edge begins before the top ends; exaggerated here): in x, y order the
    line flickers between the two and gives no clean sample; in the pixels' order it gives
    one, at the top's first column."""
    cam = CameraModel.look_at(640, 480, np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]]),
                              np.zeros(5), [0.0, -150.0, 150.0], [0.0, 0.0, 0.0],
                              [0.0, 1.0, 0.0])
    cols = np.arange(300.0, 340.0)
    origin, d = cam.rays(np.column_stack([cols, np.full(len(cols), 240.0)]))
    z = np.where(cols >= 320, 5.0, 0.0)
    pts = origin + d * ((z - origin[2]) / d[:, 2])[:, None]
    top, floor = pts[z > 0], pts[z == 0]
    assert floor[:, 1].max() > top[:, 1].min() + 1.0          # interleaved in y
    lines, table = np.zeros(len(pts), int), z == 0
    found = edge_samples(pts, lines, table, cam)
    assert len(found) == 1
    assert np.allclose(found.points[0], pts[cols == 320][0])
    by_xy = edge_samples(pts, lines, table)
    assert not (len(by_xy) == 1 and np.allclose(by_xy.points[0], pts[cols == 320][0]))


def test_the_scan_camera_is_the_height_calibrations():
    """Method 2 scans are measured through the height calibration's camera, Method 1 scans
    through the rig's."""
    from insitu.formats.calibration import HeightCalibration
    from insitu.formats.camera_spec import CameraSpec
    from insitu.services.height import scan_camera
    from insitu.sim.rig import default_rig

    rig = default_rig(binning=8)
    cal = HeightCalibration.model_construct(camera=CameraSpec.model_validate(
        rig.camera.to_dict()))
    assert scan_camera(rig.operator.camera, None) is rig.operator.camera
    got = scan_camera(rig.operator.camera, cal)
    assert np.allclose(got.K, rig.camera.K) and np.allclose(got.R, rig.camera.R)


def test_an_edges_normal_at_any_angle():
    """The insert's sides face 180° and ±60°, its hole every way: the normal edge_distance
    gives is theirs within 1° wherever a line crosses them (the hole's, a polygon of facets a
    few degrees apart, within 2°; differenced over a few pixels alone, a sharp step's normal
    reads as a multiple of 45°: the ±60° sides as ±46°)."""
    w = make_workpiece("insert")
    ref = reference_from_mesh(w.vertices, w.triangles, "insert")
    r_in, r_hole, top = 16.14 / (2 * np.sqrt(3)), 3.80 / 2, 4.68
    t = np.linspace(-3.0, 3.0, 13)
    cases = []                                        # (sample points, outward normals)
    for a in np.radians([180.0, 60.0, -60.0]):
        n = np.array([np.cos(a), np.sin(a)])
        cases.append(((r_in - 0.05) * n + t[:, None] * np.array([-n[1], n[0]]),
                      np.tile(n, (len(t), 1))))
    b = np.radians(np.arange(0.0, 360.0, 15.0) + 7.0)
    radial = np.column_stack([np.cos(b), np.sin(b)])
    cases.append(((r_hole + 0.05) * radial, -radial))
    for xy, n_true in cases:
        turn = rot_z(np.radians(25.0))[:2, :2]         # lines 25° off the normals
        u = n_true @ turn.T
        e = np.column_stack([xy, np.full(len(xy), top)])
        s, n = edge_distance(ref.heights, e, u)
        assert np.isfinite(s).all()
        err = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n, n_true), -1, 1)))
        assert err.max() < (1.0 if len(xy) == len(t) else 2.0), err   # the hole: facets


def test_a_step_beside_a_higher_wall_is_no_edge_of_its_own():
    """A line 0.02 mm inside the block's side wall ends where a step drops beside it: the
    wall's slope (10 mm down to the table) outweighs the step's there, so the normal found
    is the wall's — and a line running along the wall would then seem to hold x. Moved
    0.3 mm along that wall the line meets the step 0.2 mm away, or nothing: no sample. The
    same step 1 mm in from the wall is one, facing −y."""
    w = make_workpiece("step-block")
    ref = reference_from_mesh(w.vertices, w.triangles, "step-block")
    e = np.array([[-9.98, 0.06, 10.02], [-9.0, 0.06, 10.02]])
    s, n = edge_distance(ref.heights, e, np.array([[-0.054, -0.999], [0.0, -1.0]]))
    assert np.isnan(s[0])
    assert s[1] == pytest.approx(0.06, abs=0.02) and n[1] == pytest.approx([0, -1], abs=0.02)


def test_a_samples_direction_is_its_lines_on_the_top():
    """A line running along +y over a 10 mm top ends at y = 0; beyond the edge the floor's
    points lie 1.5 mm aside in x (the light plane leans). The sample's direction is the line's
    along the top, not the jump to the floor (which made a line grazing an edge look as if it
    crossed it square, and held the part across it: a step block 0.06 mm off in x)."""
    y = np.arange(-5.0, 5.0, 0.1)
    top = y < 0
    pts = np.column_stack([np.where(top, 0.0, 1.5), y, np.where(top, 10.0, 0.0)])
    found = edge_samples(pts, np.zeros(len(y), int), ~top)
    assert len(found) == 1
    assert np.allclose(found.dirs[0], [0.0, 1.0], atol=1e-6)
