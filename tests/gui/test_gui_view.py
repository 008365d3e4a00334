"""The 3-D view and the camera's picture through real widgets (pytest-qt, offscreen): the
View menu's projection, framing and camera colours, the colour bar's range, each pattern
drawn once, and the camera window's zoom, pan, 1:1 and fit."""

import numpy as np
import pytest
from PySide6.QtCore import QPoint, QPointF, QSettings, Qt
from PySide6.QtGui import QWheelEvent
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication
from test_gui_workflow import WAIT_MS, place, scan_recording, window

from insitu.formats.pointcloud import PointCloud
from insitu.ui.model.scene_data import AMBIENT
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.view_menu import NO_AMBIENT
from insitu.ui.qt.view_overlay import colour_bar_range

SHARED_FIXTURES = (window,)          # the connected window of the workflow tests


@pytest.fixture
def bare(qtbot, tmp_path):
    """The window without a rig: the view and its menu only."""
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(w)
    w.resize(1200, 800)
    w.show()
    qtbot.waitExposed(w)
    return w


def _cloud(n=20_000, ambient=True, z=(2.0, 17.0)) -> PointCloud:
    rng = np.random.default_rng(3)
    xy = rng.uniform((-14, -46), (14, 46), (n, 2))
    pts = np.c_[xy, z[0] + (z[1] - z[0]) * (xy[:, 1] + 46) / 92]
    attrs = {AMBIENT: (0.2 + 0.6 * (xy[:, 0] > 0)).astype(np.float32)} if ambient else {}
    return PointCloud(pts, attrs)


def _action(w, text):
    return next(a for a in w.view_menu.ortho.parent().findChildren(type(w.view_menu.ortho))
                if a.text() == text)


def _inside(view, lo, hi) -> bool:
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    px = view.camera.project(corners, view.width(), view.height())
    return bool(np.isfinite(px).all() and (px >= 0).all() and (px[:, 0] <= view.width()).all()
                and (px[:, 1] <= view.height()).all())


def test_top_view_is_orthographic_the_others_perspective_and_the_toggle(bare):
    view, menu = bare.view, bare.view_menu
    assert view.camera.ortho and menu.ortho.isChecked()          # placing: top, orthographic
    iso = _action(bare, "Iso view")
    assert iso.shortcut().toString() == "4"
    iso.trigger()
    assert not view.camera.ortho and not menu.ortho.isChecked()
    menu.ortho.trigger()                                         # View ▸ Orthographic
    assert view.camera.ortho and view.camera.elevation_deg == 35.0
    menu.ortho.trigger()
    assert not view.camera.ortho
    _action(bare, "Top view").trigger()
    assert view.camera.ortho and menu.ortho.isChecked()
    assert [s.toString() for s in menu.frame.shortcuts()] == ["F", "Home"]
    assert menu.camera_colours.shortcut().toString() == "C"


def test_a_loaded_cloud_is_framed_whole_and_frame_all_brings_it_back(bare):
    cloud = _cloud()
    lo, hi = cloud.points.min(0), cloud.points.max(0)
    bare.session.set_cloud(cloud)
    view = bare.view
    assert _inside(view, lo, hi)
    # not a close-up: the cloud fills most of the view
    px = view.camera.project(cloud.points, view.width(), view.height())
    assert np.ptp(px[:, 1]) > 0.6 * view.height()
    view.camera.zoom(0.05)
    view.camera.pan(400, 300, view.height())
    assert not _inside(view, lo, hi)
    _action(bare, "Frame all").trigger()
    assert _inside(view, lo, hi)
    _action(bare, "Iso view").trigger()
    bare.view_menu.frame.trigger()
    assert _inside(view, lo, hi)


def test_colour_bar_shows_the_clouds_z_range_and_camera_colours_toggle(bare):
    view, act = bare.view, bare.view_menu.camera_colours
    assert not act.isEnabled()                                   # no cloud yet
    plain = _cloud(ambient=False, z=(-3.5, 21.25))
    bare.session.set_cloud(plain)
    kind, lo, hi = colour_bar_range(view)
    z = plain.points[:, 2]
    assert kind == "height" and (lo, hi) == pytest.approx((z.min(), z.max()), abs=1e-9)
    assert not act.isEnabled() and act.toolTip() == NO_AMBIENT
    cloud = _cloud()
    bare.session.set_cloud(cloud)
    assert act.isEnabled() and not view.renderer.camera_colours
    layer = view.renderer.points
    # the ambient gray goes to the GPU with its point, in the buffer's (tiled) order
    order = layer.tiles.order
    assert np.array_equal(layer.ambient.data[:, 0], cloud.attributes[AMBIENT][order])
    assert np.allclose(layer.positions.data, cloud.points[order], atol=1e-4)
    version = layer.ambient.version
    act.trigger()                                                # C: camera colours
    assert view.renderer.camera_colours and colour_bar_range(view)[0] == "camera"
    assert colour_bar_range(view)[1:] == pytest.approx((0.2, 0.8), abs=1e-3)
    act.trigger()
    assert not view.renderer.camera_colours and colour_bar_range(view)[0] == "height"
    assert layer.ambient.version == version                      # a toggle uploads nothing
    bare.session.set_cloud(_cloud(ambient=False))                # a cloud without: off
    assert not act.isEnabled() and not view.renderer.camera_colours


def test_a_planned_pattern_is_drawn_once_on_the_surface(qtbot, window):
    place(qtbot, window)                                         # no cloud: as placed
    lines = window.view.renderer.lines
    projected = (lambda: sum(v[0].count for k, v in lines.items()     # one layer a pen
                             if k.startswith("projected")))
    assert lines["selected"][0].count > 0 and projected() == 0
    scan_recording(qtbot, window)
    qtbot.waitUntil(lambda: bool(window.session.plans) and window.session.plans[0].plan is not None
                    and not window.runner.running("plan"), timeout=WAIT_MS)
    plan = window.session.plans[0].plan
    assert projected() > 0
    assert lines["selected"][0].count == 0 and lines["placed"][0].count == 0
    view = window.view
    assert view.handles is not None                              # handles to move it
    assert view.handle_z == pytest.approx(np.median(plan.projection.points[:, 2]))


def _wheel(widget, xy, notches):
    pos = QPointF(*xy)
    e = QWheelEvent(pos, widget.mapToGlobal(pos), QPoint(0, 0), QPoint(0, 120 * notches),
                    Qt.NoButton, Qt.NoModifier, Qt.NoScrollPhase, False)
    QApplication.sendEvent(widget, e)


def test_the_camera_window_zooms_about_the_cursor_pans_and_shows_the_centres(qtbot, bare):
    frame = np.zeros((512, 612), np.uint8)
    frame[200:210, :] = 200
    centres = np.c_[np.arange(0, 612, 2.0), np.full(306, 204.5)]
    bare.camera_image.show_image(frame, centres, "scan: line centres")
    QTest.mouseDClick(bare.camera_image, Qt.LeftButton)          # double-click: enlarge
    win = bare.camera_dock.window_
    assert win is not None and win.isVisible()
    qtbot.waitExposed(win)
    img = win.image
    assert img.fitted and img.image.size() == bare.camera_image.image.size()
    assert len(img.centres) == len(centres)
    cursor = (300.0, 200.0)
    under = img.to_image(cursor)
    scale = img.scale
    _wheel(img, cursor, 3)
    assert img.scale == pytest.approx(scale * 1.25 ** 3) and not img.fitted
    assert np.allclose(img.to_image(cursor), under, atol=1e-9)  # the point stays put
    QTest.mousePress(img, Qt.LeftButton, Qt.NoModifier, QPoint(300, 200))
    QTest.mouseMove(img, QPoint(340, 230))
    QTest.mouseRelease(img, Qt.LeftButton, Qt.NoModifier, QPoint(340, 230))
    assert np.allclose(img.to_image((340, 230)), under, atol=1e-6)  # dragged with the mouse
    win.one_button.click()
    assert img.scale == 1.0
    win.fit_button.click()
    assert img.fitted and img.scale == pytest.approx(min(img.width() / 612, img.height() / 512))
    bare.camera_image.show_image(frame[::2, ::2], None, "inspection")  # follows the dock
    assert img.caption == "inspection" and img.image.width() == 306
    bare.camera_dock.enlarge_button.click()
    assert bare.camera_dock.window_ is win


def test_a_frame_draws_at_most_its_budget_of_points():
    from insitu.ui.qt.gl_renderer import INTERACTIVE_POINTS, REST_POINTS, Renderer

    r = Renderer()
    assert r.budget(True, 10**7) == INTERACTIVE_POINTS and r.budget(False, 10**7) == REST_POINTS
    small = 500 * 720                                   # a small view needs fewer points
    assert r.budget(True, small) < r.budget(False, small) < REST_POINTS


def test_the_colour_bars_ticks_are_round_steps_between_its_ends():
    from insitu.ui.qt.view_overlay import bar_ticks

    ticks = bar_ticks(-0.3, 24.7, 30.0, 210.0)
    values = [v for v, _ in ticks]
    assert values == pytest.approx([-0.3, 5, 10, 15, 20, 24.7])
    assert ticks[0][1] == 210.0 and ticks[-1][1] == 30.0           # lo at the bottom
    ys = [y for _, y in ticks]
    assert all(a > b for a, b in zip(ys, ys[1:]))
    assert len(bar_ticks(0.0, 0.9, 0, 100)) <= 7
    assert bar_ticks(1.0, 1.0, 0, 100) == [(1.0, 100)]
