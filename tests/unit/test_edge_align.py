"""The edge step of locating (:mod:`insitu.measure.edge_align`): the inset of each edge
sample by its gap class, so edges whose lines end differently in the image do not turn the
part; lines cut short weigh nothing in the turn; the pixel gap read through the camera."""

import numpy as np
import pytest

from insitu.geometry.camera import CameraModel
from insitu.measure.edge_align import align_edges, edge_samples
from insitu.measure.flat_icp import apply, inverse, rot_z
from insitu.measure.part_reference import reference_from_mesh
from insitu.sim.workpieces import make_workpiece

from test_locate import synthetic_scan

TRUTH = (12.0, -7.0, 33.0)


@pytest.fixture(scope="module")
def block():
    """(reference heights, edge samples in the part frame (points, dirs), their steps)."""
    w = make_workpiece("step-block")
    ref = reference_from_mesh(w.vertices, w.triangles, "step-block")
    pts, lines = synthetic_scan("step-block", TRUTH, noise=0.002)
    found = edge_samples(pts, lines, pts[:, 2] < 0.5)
    pose = inverse((np.radians(TRUTH[2]), np.array([TRUTH[0], TRUTH[1], 0.0])))
    return ref.heights, apply(pose, found.points), found.dirs @ rot_z(pose[0])[:2, :2].T, \
        found.step_mm


def _turn_deg(fit):
    return abs(np.degrees(fit.angle_rad))


def test_insets_that_differ_by_gap_class_do_not_turn_the_part(block):
    """Samples in two opposite quadrants of the part lie 2 steps further inside their edges
    (their lines ended with a wider gap in the image): one inset for all turns the part;
    an inset per gap class keeps the turn within 0.01°."""
    heights, e, u, step = block
    c = np.median(e[:, :2], axis=0)
    far = (e[:, 0] - c[0]) * (e[:, 1] - c[1]) > 0
    moved = e.copy()
    moved[far, :2] -= 2 * step[far, None] * u[far]
    gap = np.where(far, 4.0, 1.0)
    one = align_edges(heights, moved, u, step)
    by_class = align_edges(heights, moved, u, step, gap)
    assert _turn_deg(one) > 0.05, _turn_deg(one)
    assert _turn_deg(by_class) < 0.01, _turn_deg(by_class)
    assert by_class.samples > 0.9 * len(e)


def test_lines_cut_short_weigh_nothing(block):
    """Every sample up to 0.15 mm inside its edge (sampling), and a fifth of them, all on
    one side, 0.5 mm further in (their lines lost their end to the lower line in the same
    pixel columns): those weigh nothing, in the turn nor in the shift (with Huber weights
    alone the shift is 0.05 mm off)."""
    heights, e, u, step = block
    rng = np.random.default_rng(3)
    moved = e.copy()
    moved[:, :2] -= rng.uniform(0, 0.15, len(e))[:, None] * u
    far = np.flatnonzero(e[:, 0] > np.percentile(e[:, 0], 70))
    cut = rng.choice(far, len(e) // 5, replace=False)
    moved[cut, :2] -= 0.5 * u[cut]
    fit = align_edges(heights, moved, u, step, np.full(len(e), 2.0))
    assert _turn_deg(fit) < 0.005, _turn_deg(fit)
    assert np.linalg.norm(fit.shift_mm) < 0.02, fit.shift_mm


def test_the_gap_is_read_in_pixels_through_the_camera():
    """A line sampled one pixel column apart, falling off a top: the gap is the number of
    columns on to the next detected point, the step the top's mm per column (also where a
    column before the last was lost); NaN without a camera."""
    cam = CameraModel.look_at(640, 480, np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]]),
                              np.zeros(5), [0.0, 0.0, 200.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    u = np.arange(300, 340, dtype=float)        # column 318 lost; 320 … 322 dark
    u = np.concatenate([u[:18], u[19:20], u[23:]])
    for cols in (u, 640.0 - u):                 # the top on the left, then on the right
        origin, d = cam.rays(np.column_stack([cols, np.full(len(u), 240.0)]))
        z = np.where(u < 320, 5.0, 0.0)
        pts = origin + d * ((z - origin[2]) / d[:, 2])[:, None]
        table = z < 0.5
        lines = np.zeros(len(pts), int)
        found = edge_samples(pts, lines, table, cam)
        assert len(found) == 1
        assert found.gap_px[0] == pytest.approx(4.0, abs=0.05)
        per_col = np.linalg.norm(pts[17, :2] - pts[16, :2])
        assert found.step_mm[0] == pytest.approx(per_col, rel=1e-6)
        assert np.isnan(edge_samples(pts, lines, table).gap_px).all()


def test_the_scan_camera_is_the_height_calibrations():
    """Method 2 scans are measured through the height calibration's camera, Method 1 scans
    through the rig's."""
    from insitu.formats.camera_spec import CameraSpec
    from insitu.rig.files import HeightCalibration
    from insitu.services.height import scan_camera
    from insitu.sim.rig import default_rig

    rig = default_rig(binning=8)
    cal = HeightCalibration.model_construct(camera=CameraSpec.model_validate(
        rig.camera.to_dict()))
    assert scan_camera(rig.operator.camera, None) is rig.operator.camera
    got = scan_camera(rig.operator.camera, cal)
    assert np.allclose(got.K, rig.camera.K) and np.allclose(got.R, rig.camera.R)
