"""The Engrave dock as the operator uses it (pytest-qt, offscreen): the depth map of a placed
pattern's pocket in the scanned cloud — its numbers those of the depth measurement, the
cells hidden by the walls and those not measured counted and drawn apart; Engrave… armed in
the same dialog as Mark (nothing fired before Fire laser, Cancel disarms), each re-measure's
map shown as it comes, ABORT stopping it with the laser off, the end said in words, Resume
going on with it."""

from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import QSettings, Qt

from insitu.formats.pointcloud import PointCloud
from insitu.marking.engrave_depth import HIDDEN, MEASURED, UNMEASURED
from insitu.marking.engrave_record import read_record
from insitu.ui.model.depth_view import DepthSummary, measure_pocket, pocket_region
from insitu.ui.model.session import RigChoice
from insitu.ui.qt.main_window import MainWindow

WAIT_MS = 60_000
TOP_Z = 5.0                             # the blank's top (sim workpiece blank-stainless)


def square_svg(tmp_path, side_mm: float):
    path = tmp_path / "square.svg"
    path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="{side_mm}mm" '
                    f'height="{side_mm}mm" viewBox="0 0 {side_mm} {side_mm}">'
                    f'<rect width="{side_mm}" height="{side_mm}"/></svg>')
    return path


def scanned_pocket(camera_xyz, half=1.5, depth=1.5, gap=None, seed=0) -> PointCloud:
    """A scan of a square pocket ``depth`` mm deep in the blank's top, lines along y 0.1 mm
    apart: the floor the camera cannot see past the wall on its side left out (a ray to
    ``camera_xyz`` rises out of the pocket only beyond the wall), and the points of ``gap``
    ((x0, x1, y0, y1) mm: a dropout) too."""
    rng = np.random.default_rng(seed)
    xs, ys = np.arange(-4, 4.001, 0.1), np.arange(-4, 4.001, 0.02)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    x, y = gx.ravel(), gy.ravel()
    line = np.repeat(np.arange(len(xs)), len(ys))
    inside = (np.abs(x) < half) & (np.abs(y) < half)
    floor = TOP_Z - depth
    z = np.where(inside, floor, TOP_Z) + rng.normal(0, 0.002, x.size)
    run = depth * np.hypot(x - camera_xyz[0], y - camera_xyz[1]) / (camera_xyz[2] - floor)
    seen = ~inside | (x + half >= run * (x - camera_xyz[0]) / np.hypot(
        x - camera_xyz[0], y - camera_xyz[1]))
    if gap is not None:
        seen &= ~((x > gap[0]) & (x < gap[1]) & (y > gap[2]) & (y < gap[3]))
    return PointCloud(np.column_stack([x, y, z])[seen], {"line": line[seen]})


@pytest.fixture
def window(qtbot, tmp_path):
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    w.resize(1200, 800)
    w.show()
    w.connect_rig(RigChoice(workpiece="blank-stainless", binning=4))
    qtbot.waitUntil(lambda: w.station is not None, timeout=WAIT_MS)
    w.docks["engrave"].raise_()
    yield w
    w.runner.wait_all()
    qtbot.waitUntil(lambda: not w.runner.tasks, timeout=WAIT_MS)
    w.saved.mark_clean()
    w.close()
    w.deleteLater()


def place_on(qtbot, w, cloud, pattern, width):
    w.session.set_cloud(cloud)
    assert w.place_panel.add_pattern(str(pattern))
    w.session.update_selected(at_mm=(0.0, 0.0), width_mm=width)
    qtbot.waitUntil(lambda: w.engrave_panel.selected() is not None
                    and not w.runner.running("plan") and not w._plan_timer.isActive(),
                    timeout=WAIT_MS)


def test_the_depth_map_of_a_pocket_shows_the_measured_numbers_and_the_hidden_cells(
        qtbot, window, tmp_path):
    rig = window.station.rig
    cloud = scanned_pocket(rig.camera.centre_world, gap=(-0.2, 1.3, -1.2, 0.4))
    place_on(qtbot, window, cloud, square_svg(tmp_path, 3.0), 3.0)
    panel = window.engrave_panel
    assert panel.mapButton.isEnabled()
    qtbot.mouseClick(panel.mapButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: panel.last_map is not None, timeout=WAIT_MS)
    # what the depth measurement gives on the same cloud and pocket
    placement, plan = panel.selected()
    truth = measure_pocket(cloud, pocket_region(plan, "square"), rig)
    dm, summary = panel.last_map
    assert np.array_equal(dm.state, truth.state)
    assert summary == DepthSummary.of(truth)
    hidden, unmeasured = truth.count(HIDDEN), truth.count(UNMEASURED)
    # 1.5 mm deep: the walls the lines cross keep 0.575 mm, the walls along them 0.825 mm
    # (0.55 × the depth); about 1.35 × 1.85 mm of the 3 mm floor is left to measure
    assert hidden > 0 and unmeasured > 0 and truth.count(MEASURED) > 30
    mean = truth.mean_depth()[0]
    assert abs(mean - 1.5) < 0.002
    cells = truth.depth[truth.state == MEASURED]
    lo, hi = np.percentile(cells, [2.5, 97.5])
    text = panel.mapLabel.text()
    assert f"mean depth {mean:.4f} mm" in text
    assert f"between {lo:.4f} and {hi:.4f} mm deep" in text
    assert f"{hidden} cells hidden by the walls" in text
    assert f"{unmeasured} cells not measured" in text
    # the picture: the hidden cells' light grey and the unmeasured cells' darker grey show
    img = panel.picture.image
    assert img is not None and "depth map" in panel.picture.caption
    pixels = {img.pixelColor(x, y).name() for x in range(0, img.width(), 2)
              for y in range(0, img.height(), 2)}
    assert "#cccccc" in pixels and "#8c8c8c" in pixels


def test_engrave_is_armed_first_shows_each_remeasure_and_abort_stops_it(qtbot, window,
                                                                        tmp_path):
    flat = scanned_pocket(window.station.rig.camera.centre_world, depth=0.0)
    place_on(qtbot, window, flat, square_svg(tmp_path, 2.0), 2.0)
    panel, world = window.engrave_panel, window.station.world
    panel.depthSpin.setValue(0.3)
    panel.rescanSpin.setValue(2)
    qtbot.mouseClick(panel.engraveButton, Qt.LeftButton)
    dlg = panel.arm_dialog
    qtbot.waitUntil(lambda: dlg.isVisible(), timeout=WAIT_MS)
    rows = dict(dlg.rows)
    assert rows["target depth"] == "0.3 mm" and rows["material"].startswith("stainless-steel")
    out = Path(rows["report"])
    # armed: nothing fired, nothing written; Cancel disarms
    assert not world.engravings and world.laser.kind == "off" and not world.burns
    dlg.reject()
    assert panel.resultLabel.text() == "disarmed: nothing was engraved"
    assert not world.engravings and panel.engraveButton.isEnabled()
    qtbot.mouseClick(panel.engraveButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: panel.arm_dialog is not None and panel.arm_dialog.isVisible(),
                    timeout=WAIT_MS)
    assert not world.engravings and not out.exists()
    qtbot.mouseClick(panel.arm_dialog.fire_button, Qt.LeftButton)
    abort = window.mark_panel.abort_action          # the Laser menu's ABORT (Esc, Space)
    qtbot.waitUntil(abort.isEnabled, timeout=WAIT_MS)
    assert panel.abortButton.isEnabled() and not panel.engraveButton.isEnabled()
    # the first re-measure's map, as the service recorded it
    qtbot.waitUntil(lambda: panel.last_map is not None, timeout=WAIT_MS)
    dm, summary = panel.last_map
    m = read_record(out).measures[0]
    assert m["round"] == 1 and m["cells"]["measured"] > 0
    assert summary.mean == pytest.approx(m["mean_mm"], abs=1e-6)
    assert summary.p95 == pytest.approx(m["cell_p95_mm"], abs=1e-6)
    assert summary.counts == m["cells"] and summary.target == 0.3
    text = panel.mapLabel.text()
    assert text.startswith(f"after round 1: {m['at_depth']} cells at depth, {m['short']} short")
    assert f"mean depth {m['mean_mm']:.4f} mm" in text
    assert f"within ±{m['cell_p95_mm']:.4f} mm of the target 0.3 mm" in text
    assert "after round 1" in panel.picture.caption
    abort.trigger()
    qtbot.waitUntil(lambda: not window.runner.running("engrave"), timeout=WAIT_MS)
    record = read_record(out)
    assert record.state == "cancelled" and world.laser.kind == "off"
    assert panel.resultLabel.text().startswith("stopped (ABORT) after")
    assert str(out) in panel.resultLabel.text()
    assert not abort.isEnabled() and panel.engraveButton.isEnabled()
    # Resume arms the stopped engraving again (measured first); ABORT stops it once more
    rounds = len(record.rounds)
    assert panel.resumeButton.isEnabled()
    qtbot.mouseClick(panel.resumeButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: panel.arm_dialog is not None and panel.arm_dialog.isVisible(),
                    timeout=WAIT_MS)
    rows = dict(panel.arm_dialog.rows)
    assert rows["report"] == str(out) and rows["run"].startswith("resume: the pocket is "
                                                                 "measured first")
    qtbot.mouseClick(panel.arm_dialog.fire_button, Qt.LeftButton)
    qtbot.waitUntil(abort.isEnabled, timeout=WAIT_MS)
    assert not panel.resumeButton.isEnabled()
    abort.trigger()
    qtbot.waitUntil(lambda: not window.runner.running("engrave"), timeout=WAIT_MS)
    record = read_record(out)
    assert record.state == "cancelled" and len(record.rounds) == rounds
    assert panel.resultLabel.text().startswith("stopped (ABORT) after")
    assert world.laser.kind == "off" and panel.resumeButton.isEnabled()


def test_measure_pocket_scans_it_on_the_rig_and_maps_its_depth(qtbot, window, tmp_path):
    flat = scanned_pocket(window.station.rig.camera.centre_world, depth=0.0)
    place_on(qtbot, window, flat, square_svg(tmp_path, 2.0), 2.0)
    panel, world = window.engrave_panel, window.station.world
    assert panel.measureButton.isEnabled()
    qtbot.mouseClick(panel.measureButton, Qt.LeftButton)
    assert panel.abortButton.isEnabled() and not panel.engraveButton.isEnabled()
    qtbot.waitUntil(lambda: panel.last_map is not None, timeout=WAIT_MS)
    dm, summary = panel.last_map
    # the pocket's cells from a scan of its own, the top around it (2 mm) measured too
    assert not world.engravings and summary == DepthSummary.of(dm)
    assert summary.counts["measured"] > 20 and np.isfinite(summary.mean)
    assert dm.cells.inside.sum() == sum(summary.counts.values())
    assert f"mean depth {summary.mean:.4f} mm" in panel.mapLabel.text()
    assert "measured on the rig" in panel.picture.caption
    qtbot.waitUntil(lambda: not panel.abortButton.isEnabled(), timeout=WAIT_MS)
    assert panel.engraveButton.isEnabled() and world.laser.kind == "off"
