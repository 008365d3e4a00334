"""The 3-D view's Qt-free maths: the orthographic projection, framing, the grid, rulers and
scale bar, and which points of a large cloud a frame draws."""

import numpy as np
import pytest

from insitu.ui.model import view_guides as vg
from insitu.ui.model.cloud_lod import MAX_STRIDE, TiledCloud, draw_ranges
from insitu.ui.model.orbit_camera import FRAME_MARGIN, OrbitCamera

W, H = 900, 600


def _top(ortho=True, distance=200.0) -> OrbitCamera:
    cam = OrbitCamera(centre=np.array([3.0, -2.0, 0.0]), distance_mm=distance)
    cam.set_view("top")
    cam.ortho = ortho
    return cam


# -- orthographic -----------------------------------------------------------------------
def test_top_view_is_orthographic_and_heights_do_not_move_points():
    cam = OrbitCamera()
    cam.set_view("top")
    assert cam.ortho
    outline = np.array([[-5.0, -3.0], [5.0, -3.0], [5.0, 3.0], [-5.0, 3.0]])
    at = {z: cam.project(np.c_[outline, np.full(4, z)], W, H) for z in (0.0, 5.0, 15.0)}
    assert np.allclose(at[0.0], at[5.0], atol=1e-9) and np.allclose(at[0.0], at[15.0])
    cam.ortho = False                                     # perspective: the higher, the larger
    assert np.ptp(cam.project(np.c_[outline, np.full(4, 15.0)], W, H)[:, 0]) > \
        np.ptp(cam.project(np.c_[outline, np.zeros(4)], W, H)[:, 0]) + 1
    for name in ("front", "side", "iso"):
        cam.set_view(name)
        assert not cam.ortho


def test_ortho_keeps_the_scale_at_the_centre_and_picking_is_exact():
    persp, ortho = _top(False), _top(True)
    p = np.array([[3.0, -2.0, 0.0], [13.0, -2.0, 0.0]])
    assert np.allclose(persp.project(p, W, H), ortho.project(p, W, H), atol=1e-6)
    assert ortho.mm_per_px(H) == pytest.approx(10.0 / np.ptp(ortho.project(p, W, H)[:, 0]))
    cam = OrbitCamera(centre=np.array([5.0, -3.0, 2.0]), distance_mm=150, azimuth_deg=-30,
                      elevation_deg=40, ortho=True)
    pts = np.array([[20.0, 10.0, 0.0], [-15.0, 4.0, 12.0], [0.0, 0.0, -8.0]])
    for pt, (x, y) in zip(pts, cam.project(pts, W, H)):
        assert np.allclose(cam.pick_plane(x, y, W, H, pt[2]), pt, atol=1e-6)


@pytest.mark.parametrize("view", ["top", "iso", "front"])
@pytest.mark.parametrize("aspect_wh", [(900, 600), (500, 720)])
def test_frame_fits_the_whole_box_and_fills_the_view(view, aspect_wh):
    w, h = aspect_wh
    lo, hi = np.array([-14.0, -46.0, 0.0]), np.array([14.0, 46.0, 15.0])
    cam = OrbitCamera(distance_mm=3000.0)                 # start far away: no close-up either
    cam.set_view(view)
    cam.frame(lo, hi, w / h)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    px = cam.project(corners, w, h)
    assert (px >= 0).all() and (px[:, 0] <= w).all() and (px[:, 1] <= h).all()
    ndc = np.abs(px / (w, h) * 2 - 1)
    assert ndc.max() == pytest.approx(FRAME_MARGIN, abs=0.02)     # fills it: not tiny


# -- grid, rulers, scale bar -------------------------------------------------------------
def test_nice_steps():
    assert [vg.nice_step(x) for x in (0.3, 1.0, 1.1, 2.5, 7.0, 11.0)] == [0.5, 1, 2, 5, 10, 20]
    assert [vg.nice_floor(x) for x in (0.3, 1.9, 2.5, 7.0, 11.0)] == [0.2, 1, 2, 5, 10]
    assert [vg.major_every(s) for s in (0.1, 0.2, 0.5, 1, 2, 5, 10)] == [10, 5, 2, 10, 5, 2, 10]


def test_grid_spacing_follows_the_zoom():
    cam = _top()
    g = vg.grid(cam, W, H)
    assert g.step_mm / cam.mm_per_px(H) >= vg.GRID_MIN_PX
    assert g.step_mm / cam.mm_per_px(H) < 2.5 * vg.GRID_MIN_PX
    cam.zoom(0.1)
    g2 = vg.grid(cam, W, H)
    assert g2.step_mm < g.step_mm / 5
    # lines on multiples of the step, on z = 0, covering the view
    def x_lines(v):                                    # x of the lines along y
        a, b = v[0::2], v[1::2]
        return a[a[:, 0] == b[:, 0], 0]
    xs = np.unique(np.r_[x_lines(g2.minor), x_lines(g2.major)])
    assert np.allclose(xs / g2.step_mm, np.round(xs / g2.step_mm), atol=1e-4)
    assert (g2.minor[:, 2] == 0).all()
    x0, x1, y0, y1 = vg.visible_plane_box(cam, W, H)
    assert xs.min() - g2.step_mm < x0 and xs.max() + g2.step_mm > x1
    every = g2.step_mm * vg.major_every(g2.step_mm)
    assert len(x_lines(g2.major)) and np.allclose(x_lines(g2.major) % every, 0, atol=1e-4)


def test_rulers_label_where_the_world_coordinates_are():
    cam = _top()
    rulers = {r.edge: r for r in vg.rulers(cam, W, H)}
    bottom, left = rulers["bottom"], rulers["left"]
    assert bottom.axis == 0 and left.axis == 1
    assert len(bottom.values_mm) >= 3 and len(left.values_mm) >= 3
    px = cam.project(np.c_[bottom.values_mm, np.zeros((len(bottom.values_mm), 2))], W, H)
    assert np.allclose(bottom.positions_px, px[:, 0], atol=0.01)
    py = cam.project(np.c_[np.zeros(len(left.values_mm)), left.values_mm,
                           np.zeros(len(left.values_mm))], W, H)
    assert np.allclose(left.positions_px, py[:, 1], atol=0.01)
    assert np.diff(bottom.positions_px).min() >= vg.RULER_MIN_PX - 1


def test_scale_bar_is_a_nice_length_at_the_view_scale():
    cam = _top()
    mm, px = vg.scale_bar(cam, H)
    assert px == pytest.approx(mm / cam.mm_per_px(H)) and px <= vg.SCALE_BAR_PX
    assert mm == vg.nice_floor(mm) and 2.5 * px > vg.SCALE_BAR_PX
    cam.zoom(0.25)
    assert vg.scale_bar(cam, H)[0] < mm


def test_axes_start_at_the_origin_a_nice_length_long():
    cam = _top()
    length, lines = vg.axes(cam, H)
    assert length == vg.nice_step(length)
    assert np.allclose(lines[0::2], 0) and np.allclose(lines[1::2], np.eye(3) * length)
    px = cam.project(lines[:4], W, H)
    assert vg.AXIS_PX <= np.linalg.norm(px[1] - px[0]) < 2.5 * vg.AXIS_PX


# -- level of detail ---------------------------------------------------------------------
def _scan_cloud(n=200_000, lines=200):
    per = n // lines
    x = np.repeat(np.linspace(-50, 50, lines), per)
    y = np.tile(np.linspace(-50, 50, per), lines)
    return np.c_[x, y, np.sin(x / 10)]


def test_tiles_keep_scan_order_and_every_point():
    pts = _scan_cloud()
    t = TiledCloud.of(pts)
    assert sorted(t.order.tolist()) == list(range(len(pts)))
    assert np.allclose(t.points, pts[t.order].astype(np.float32))
    for s, e in zip(t.starts, t.ends):                      # scan order inside each tile
        assert (np.diff(t.order[s:e]) > 0).all()
        assert (t.points[s:e] >= t.lo[s == t.starts][0] - 1e-4).all()


def test_a_frame_draws_the_tiles_in_view_within_the_budget():
    pts = _scan_cloud()
    t = TiledCloud.of(pts)
    cam = _top(distance=200.0)
    cam.centre = np.zeros(3)
    mvp = cam.mvp(W / H)
    starts, ends = t.visible_runs(mvp)
    assert ends.sum() - starts.sum() == len(pts)                # all in view
    k, first, count = draw_ranges(starts, ends, 50_000)
    assert k == 4 and count.sum() <= 50_000 + len(first)
    drawn = np.concatenate([np.arange(f, f + c) * k for f, c in zip(first, count)])
    assert drawn.max() < len(pts) and (drawn % k == 0).all()
    cam.zoom(0.1)                                               # zoomed in: a few tiles,
    cam.centre = np.array([20.0, 20.0, 0.0])                    # every point of them
    starts, ends = t.visible_runs(cam.mvp(W / H))
    visible = int((ends - starts).sum())
    assert 0 < visible < len(pts) / 20
    k, first, count = draw_ranges(starts, ends, 50_000)
    assert k == 1 and count.sum() == visible
    inside = np.abs(pts[:, :2] - (20, 20)).max(1) < 5
    drawn = np.concatenate([t.order[s:e] for s, e in zip(starts, ends)])
    assert np.isin(np.flatnonzero(inside), drawn).all()        # nothing in view left out


def test_stride_is_bounded_by_gl():
    k, first, count = draw_ranges(np.array([0]), np.array([10**9]), 1000)
    assert k == MAX_STRIDE
