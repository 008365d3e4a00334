"""Projection of placed polylines onto a measured cloud, and the safety checks before a job."""

import numpy as np
import pytest

from insitu.errors import SafetyError
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import Limits, Surface, check_projection, check_targets, densify, project
from insitu.marking.project import project_planar, project_wrap

R_ARC, APEX = 42.5, 11.5           # the arc workpiece's cylinder (axis along y)


def grid_cloud(f, x0=-30, x1=30, y0=-30, y1=30, step=0.25, jitter=0.0, seed=0):
    rng = np.random.default_rng(seed)
    X, Y = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    x = X.ravel() + rng.uniform(-jitter, jitter, X.size)
    y = Y.ravel() + rng.uniform(-jitter, jitter, X.size)
    return np.column_stack([x, y, f(x, y)])


def tilted(x, y):
    return 5.0 + np.tan(np.radians(15)) * x - 0.1 * y


def cylinder(x, y):
    return APEX - R_ARC + np.sqrt(R_ARC**2 - x**2)


def length3d(p):
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def test_planar_on_tilted_plane_is_exact():
    cloud = grid_cloud(tilted, jitter=0.08)
    lines = [np.array([[-10.0, -5.0], [12.0, 7.0]]), np.array([[0, 0], [3.3, -9.1], [-4, 2.0]])]
    proj = project(lines, cloud, "planar")
    assert len(proj.paths) == 2
    for src, out in zip(lines, proj.paths):
        assert out.shape[1] == 3
        np.testing.assert_allclose(out[[0, -1], :2], src[[0, -1]])      # x, y kept
        assert np.abs(out[:, 2] - tilted(out[:, 0], out[:, 1])).max() < 0.01
        seg = np.linalg.norm(np.diff(out[:, :2], axis=0), axis=1)
        assert seg.max() <= proj.step_mm + 1e-9
    assert proj.step_mm <= Surface(cloud).spacing_mm + 1e-9
    assert proj.max_stretch == 0.0


def test_planar_rejects_outliers():
    cloud = grid_cloud(lambda x, y: np.full_like(x, 2.0), step=0.2)
    rng = np.random.default_rng(3)
    spikes = rng.choice(len(cloud), len(cloud) // 30, replace=False)
    cloud[spikes, 2] += rng.choice([-3.0, 4.0], len(spikes))
    proj = project([np.array([[-20.0, -20], [20, 20]])], cloud)
    assert np.abs(proj.points[:, 2] - 2.0).max() < 0.01


def test_densification_follows_a_step():
    cloud = grid_cloud(lambda x, y: np.where(y > 0.0, 5.0, 0.0), step=0.2)
    proj = project_planar([np.array([[1.0, -4.0], [1.0, 4.0]])], cloud)
    p = np.vstack(proj.paths)
    assert len(p) > 30                                        # densified, not 2 points
    assert np.diff(p[:, 1]).max() <= proj.step_mm + 1e-9
    far = np.abs(p[:, 1]) > 2 * proj.step_mm
    np.testing.assert_allclose(p[far, 2], np.where(p[far, 1] > 0, 5.0, 0.0), atol=1e-6)
    # the path is cut where it drops, within one step of the wall; each level is flat
    low, high = proj.paths
    assert abs(low[-1, 1]) <= 2 * proj.step_mm and high[0, 1] - low[-1, 1] <= proj.step_mm + 1e-9
    assert np.ptp(low[:, 2]) < 1e-6 and np.ptp(high[:, 2]) < 1e-6


def test_densify_keeps_vertices_and_short_segments():
    poly = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.05], [3.0, 2.0]])
    (out,) = densify([poly], 0.1)
    for v in poly:
        assert np.min(np.linalg.norm(out - v, axis=1)) < 1e-12
    assert np.linalg.norm(np.diff(out, axis=0), axis=1).max() <= 0.1 + 1e-12
    single = densify([np.array([[2.0, 3.0]])], 0.1)[0]
    assert single.shape == (1, 2)


@pytest.mark.parametrize("line", [
    [[-15.0, 0.0], [15.0, 0.0]],          # across the axis: the arc unrolls
    [[0.0, -15.0], [0.0, 15.0]],          # along the axis
    [[-12.0, -8.0], [13.0, 9.0]],         # diagonal, off centre
])
def test_wrap_keeps_arc_length_on_a_cylinder(line):
    cloud = grid_cloud(cylinder, -20, 20, -20, 20, step=0.15, jitter=0.03)
    line = np.array(line) + [1.5, -2.0]
    proj = project_wrap([line], cloud)
    L = length3d(proj.paths[0])
    L0 = float(np.linalg.norm(line[1] - line[0]))
    assert abs(L - L0) / L0 < 0.005
    assert proj.mode == "wrap" and proj.max_stretch < 0.005
    np.testing.assert_allclose(proj.paths[0][:, 2], cylinder(*proj.paths[0][:, :2].T), atol=0.01)


def test_wrap_30mm_line_differs_from_planar():
    cloud = grid_cloud(cylinder, -20, 20, -20, 20, step=0.15)
    line = [np.array([[-15.0, 0.0], [15.0, 0.0]])]
    wrap, planar = project(line, cloud, "wrap"), project(line, cloud, "planar")
    assert abs(length3d(wrap.paths[0]) - 30.0) < 0.15
    assert length3d(planar.paths[0]) > 30.6                  # planar stretches it on the arc
    assert np.ptp(wrap.paths[0][:, 0]) < 29.5                # wrap pulls the ends in


def test_wrap_square_on_cylinder_keeps_sides():
    cloud = grid_cloud(cylinder, -20, 20, -20, 20, step=0.15)
    sq = np.array([[-12.0, -12], [12, -12], [12, 12], [-12, 12], [-12, -12]])
    sides = [sq[i:i + 2] for i in range(4)]
    proj = project_wrap(sides, cloud, anchor=(0.0, 0.0))
    for p in proj.paths:
        assert abs(length3d(p) - 24.0) / 24.0 < 0.005
    # the sides still meet at the corners
    for i in range(4):
        np.testing.assert_allclose(proj.paths[i][-1], proj.paths[(i + 1) % 4][0], atol=1e-9)


def test_wrap_reports_stretch_on_a_sphere():
    R = 40.0
    cloud = grid_cloud(lambda x, y: np.sqrt(R**2 - x**2 - y**2) - 30, -25, 25, -25, 25, 0.2)
    proj = project_wrap([np.array([[-15.0, -15], [15, -15], [15, 15], [-15, 15.0]])], cloud)
    assert 0.01 < proj.max_stretch < 0.5                       # not developable: reported


def test_wrap_on_tilted_plane_is_an_isometry():
    cloud = grid_cloud(tilted, step=0.25)
    sq = np.array([[-10.0, -10], [10, -10], [10, 10], [-10, 10], [-10, -10]])
    proj = project_wrap([sq], cloud)
    assert proj.max_stretch < 1e-3
    assert abs(length3d(proj.paths[0]) - 80.0) < 0.08


# ------------------------------------------------------------------------------ checks
LIMITS = Limits((200.0, 200.0), (-25.0, 25.0), 60.0)


def test_checks_pass_a_good_pattern():
    cloud = grid_cloud(cylinder, -20, 20, -20, 20, step=0.2)
    for mode in ("planar", "wrap"):
        check_projection(project([np.array([[-10.0, -3], [10, 4]])], cloud, mode), LIMITS)


def test_check_outside_field():
    cloud = grid_cloud(lambda x, y: np.full_like(x, 1.0), 90, 110, -5, 5, 0.2)
    proj = project([np.array([[95.0, 0.0], [104.0, 0.0]])], cloud)
    with pytest.raises(SafetyError, match=r"\(x, y\) = \(100\.\d+, 0\.000\) mm is outside the "
                                          r"scan field ±100"):
        check_projection(proj, LIMITS)


def test_check_outside_field_at_height_through_the_head():
    head = TwoMirrorHead(350.0, 12.0)
    ok = np.array([[97.0, 0.0, 0.0]])
    check_targets(ok, Limits(head=head))
    with pytest.raises(SafetyError, match=r"outside the scan field .* on z = 0"):
        check_targets(np.array([[97.0, 0.0, 20.0]]), Limits(head=head))   # beam at 102.9


def test_check_outside_focus_range():
    cloud = grid_cloud(lambda x, y: 20 + 0.5 * x, -10, 10, -10, 10, 0.2)   # 15 … 25 mm
    proj = project([np.array([[0.0, 0.0], [9.0, 0.0]])], cloud)
    with pytest.raises(SafetyError, match=r"\(9\.000, 0\.000\) mm at height z = 24\.500 mm is "
                                          r"outside the focus range -25 … 24 mm"):
        check_projection(proj, Limits(z_range_mm=(-25.0, 24.0)))


def test_check_over_a_hole():
    cloud = grid_cloud(lambda x, y: np.full_like(x, 3.0), -15, 15, -15, 15, 0.2)
    cloud = cloud[np.hypot(cloud[:, 0] - 4.0, cloud[:, 1] - 2.0) > 2.5]      # a 5 mm hole
    proj = project([np.array([[-10.0, 2.0], [10.0, 2.0]])], cloud)
    with pytest.raises(SafetyError, match=r"at \(x, y\) = \(\d\.\d+, 2\.000\) mm is over a hole"
                                          r" in the point cloud") as e:
        check_projection(proj, LIMITS)
    x = float(str(e.value).split("(x, y) = (")[1].split(",")[0])
    assert 1.5 - proj.step_mm <= x <= 6.5
    check_projection(project([np.array([[-10.0, -5.0], [10.0, -5.0]])], cloud), LIMITS)


def test_check_outside_the_scanned_area():
    cloud = grid_cloud(lambda x, y: np.full_like(x, 3.0), -10, 10, -10, 10, 0.2)
    proj = project([np.array([[0.0, 0.0], [14.0, 0.0]])], cloud)
    with pytest.raises(SafetyError, match="over a hole"):
        check_projection(proj, LIMITS)


def test_a_line_across_a_step_is_split_at_the_edge():
    cloud = grid_cloud(lambda x, y: np.where(y > 0.0, 10.0, 5.0), -10, 10, -10, 10, 0.2)
    proj = project([np.array([[3.0, -5.0], [3.0, 5.0]])], cloud)
    check_projection(proj, LIMITS)                 # a vertical step has nothing to mark on
    low, high = proj.paths
    assert np.allclose(low[:, 2], 5.0, atol=1e-6) and np.allclose(high[:, 2], 10.0, atol=1e-6)
    assert abs(low[-1, 1]) <= 0.2 + 1e-9 and abs(high[0, 1]) <= 0.2 + 1e-9 and high[0, 1] > low[-1, 1]
    assert np.allclose(proj.slope_deg, 0.0, atol=1.0)


def test_check_over_a_steep_chamfer():
    chamfer = lambda x, y: np.clip(np.tan(np.radians(70)) * y, 0.0, 5.0)   # 70° from y = 0
    cloud = grid_cloud(chamfer, -10, 10, -10, 10, 0.1)
    proj = project([np.array([[3.0, -5.0], [3.0, 5.0]])], cloud)
    with pytest.raises(SafetyError, match=r"\(3\.000, \d\.\d+\) mm is over a wall steeper than "
                                          r"60° \(local surface slope \d+\.\d°\)"):
        check_projection(proj, LIMITS)
    check_projection(proj, Limits(max_slope_deg=75.0))   # fine with a limit beyond its slope
    check_projection(project([np.array([[3.0, 3.0], [3.0, 5.0]])], cloud), LIMITS)  # beside it


def test_moderate_slope_is_not_a_wall():
    cloud = grid_cloud(lambda x, y: np.tan(np.radians(40)) * x, -10, 10, -10, 10, 0.2)
    proj = project([np.array([[-5.0, 0.0], [5.0, 3.0]])], cloud)
    assert np.allclose(proj.slope_deg, 40.0, atol=0.5)
    check_projection(proj, LIMITS)
    with pytest.raises(SafetyError, match="steeper than 30°"):
        check_projection(proj, Limits(max_slope_deg=30.0))


def test_pattern_entirely_off_the_cloud_is_refused():
    cloud = grid_cloud(lambda x, y: np.full_like(x, 3.0), -10, 10, -10, 10, 0.2)
    with pytest.raises(SafetyError, match=r"\(x, y\) = \(50\.000, 0\.000\) mm is outside the "
                                          "scanned area"):
        project([np.array([[45.0, 0.0], [55.0, 0.0]])], cloud)


def test_a_step_seen_with_a_gap_where_the_lines_break_is_two_levels():
    """Lines along y every 0.5 mm over a 2 mm step at y = 0, each losing a different stretch
    around the edge (shadow, dropped columns): to the neighbours of a point beside the gap the
    rise looks like a 60–70° slope, but no point lies on it — the point keeps its own level,
    flat (it was planned as a 65° wall and the pattern refused)."""
    xs, ys = np.meshgrid(np.arange(-5.0, 5.01, 0.5), np.arange(-5.0, 5.0, 0.15))
    x, y = xs.ravel(), ys.ravel()
    odd = np.round(x / 0.5).astype(int) % 2 == 1
    keep = np.where(odd, (y < -0.3) | (y > 0.1), (y < -0.6) | (y > 0.5))
    z = np.where(y > 0.0, 5.0, 3.0)
    cloud = np.column_stack([x[keep], y[keep], z[keep]])
    s = Surface(cloud).sample(np.array([[0.25, -0.35], [0.75, -0.3], [0.25, 0.2]]))
    np.testing.assert_allclose(s.z, [3.0, 3.0, 5.0], atol=1e-6)
    assert (s.slope_deg < 1.0).all()


def gapped_step(shift=0.0):
    """Lines along y every 0.5 mm (points 0.15 mm apart) over a 3 → 5 mm step at y = 0, as the
    camera sees it: the lower level lost 0.2–0.4 mm behind the top edge, the upper level's
    lines stopping 0–0.2 mm short of it; ``shift``: the upper level's last points measured
    that far past the true edge (lateral error)."""
    xs, ys = np.meshgrid(np.arange(-6.0, 6.01, 0.5), np.arange(-6.0, 6.0, 0.15) + 0.01)
    x, y = xs.ravel(), ys.ravel()
    line = np.round((x + 6.0) / 0.5).astype(int)
    lost_low = 0.2 + 0.2 * ((line * 7) % 5) / 4                # 0.2 … 0.4 mm
    short_high = 0.2 * ((line * 3) % 5) / 4 - shift           # 0 … 0.2 mm
    keep = (y < -lost_low) | (y > short_high)
    z = np.where(y > 0.0, 5.0, 3.0)
    return np.column_stack([x[keep], y[keep], z[keep]])


def true_step(p):
    return np.where(p[:, 1] > 0.0, 5.0, 3.0)


@pytest.mark.parametrize("shift", [0.0, 0.03])
def test_nothing_is_marked_in_the_strip_a_step_leaves_unmeasured(shift):
    """Issue 11: hatch lines across and along a step whose wall the cloud does not show: every
    target within 0.10 mm of the true surface, the strip between the levels left unmarked,
    and the projection says how much."""
    cloud = gapped_step(shift)
    across = [np.array([[x, -3.0], [x, 3.0]]) for x in np.arange(-4.0, 4.01, 0.05)]
    along = [np.array([[-4.0, y], [4.0, y]]) for y in np.arange(-1.0, 1.0, 0.05)]
    for lines in (across, along):
        proj = project(lines, cloud)
        check_projection(proj, LIMITS)
        p = proj.points
        assert np.abs(p[:, 2] - true_step(p)).max() < 0.10
        assert not ((p[:, 1] > -0.2) & (p[:, 1] < 0.0)).any()   # lower level not seen there
        assert 0.0 < proj.unmarked_mm < proj.path_mm
        kept = sum(float(np.linalg.norm(np.diff(q[:, :2], axis=0), axis=1).sum())
                   for q in proj.paths)
        assert proj.unmarked_mm == pytest.approx(proj.path_mm - kept)
    assert 0.1 < proj.unmarked_fraction < 0.5                  # along: rows in the strip
    assert not (np.abs(proj.points[:, 1] + 0.1) < 0.01).any()  # the row at y = −0.1: none


def test_beyond_a_levels_last_point_less_is_measured_as_the_levels_lie_apart():
    """The levels' facing points 1.45 spacings apart, the upper's last 0.02 mm over the true
    edge (the step block on the simulated rig): a target 0.07 mm beyond it is unmeasured — a
    half spacing's allowance (a fully measured step's) marked it 2 mm high; 0.03 mm beyond
    it, still within the upper's measured extent, is measured."""
    x = np.arange(-3.0, 3.01, 0.5)
    upper = -0.02 + 0.15 * np.arange(40)
    lower = -0.02 - 1.45 * 0.15 - 0.15 * np.arange(40)
    cloud = np.vstack([np.column_stack([np.repeat(x, len(y)), np.tile(y, len(x)),
                                        np.full(len(x) * len(y), z)])
                       for y, z in ((upper, 5.0), (lower, 3.0))])
    s = Surface(cloud).sample(np.array([[0.0, -0.09], [0.0, -0.05], [0.0, 0.05]]))
    assert s.unmeasured.tolist() == [True, False, False]
    np.testing.assert_allclose(s.z[1:], 5.0, atol=1e-6)


def test_a_fully_measured_step_keeps_its_paths_whole():
    cloud = grid_cloud(lambda x, y: np.where(y > 0.0, 5.0, 3.0), -6, 6, -6, 6, 0.15)
    proj = project([np.array([[1.0, -3.0], [1.0, 3.0]])], cloud)
    low, high = proj.paths
    assert high[0, 1] - low[-1, 1] <= proj.step_mm + 1e-9
    assert proj.unmarked_mm == pytest.approx(high[0, 1] - low[-1, 1])
    flat = project([np.array([[1.0, -3.0], [1.0, 3.0]])], grid_cloud(tilted))
    assert flat.unmarked_mm == 0.0 and flat.path_mm == pytest.approx(6.0)


def test_a_wrapped_path_leaves_the_strip_out_too():
    proj = project([np.array([[1.0, -3.0], [1.0, 3.0]])], gapped_step(), "wrap",
                   anchor=(1.0, -2.0), direction_deg=90.0)
    p = proj.points
    assert len(proj.paths) == 2 and proj.unmarked_mm > 0.2
    assert np.abs(p[:, 2] - true_step(p)).max() < 0.10


def test_a_pattern_wholly_in_the_unmeasured_strip_is_refused():
    with pytest.raises(SafetyError, match=r"\(x, y\) = \(-2\.000, -0\.100\) mm lies beside a "
                                          "step, where the cloud does not show the surface"):
        project([np.array([[-2.0, -0.1], [2.0, -0.1]])], gapped_step())
