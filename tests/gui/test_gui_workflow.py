"""The operator's workflows in the main window (pytest-qt, offscreen): scan a recorded
sequence, place a pattern with mouse drags, undo, check and mark the job, save and reopen
the project, and the one-line messages for bad input."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from PySide6.QtCore import QMimeData, QPoint, QPointF, QSettings, Qt, QUrl
from PySide6.QtGui import QDropEvent
from PySide6.QtTest import QTest

from insitu import services
from insitu.ui.model.session import RigChoice
from insitu.ui.qt.main_window import MainWindow

DATA = Path(__file__).parents[1] / "data"
SCAN = DATA / "scan-step-block-b4"
ROOT = Path(__file__).parents[2]
WAIT_MS = 60_000


@pytest.fixture
def window(qtbot, tmp_path, height_cal_file):
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    w.resize(1200, 800)
    w.show()
    w.connect_rig(RigChoice(binning=4))
    w.load_height_cal(height_cal_file)
    qtbot.waitUntil(lambda: w.station is not None and w.session.height_cal is not None,
                    timeout=WAIT_MS)
    yield w
    w.runner.wait_all()
    qtbot.waitUntil(lambda: not w.runner.tasks, timeout=WAIT_MS)   # their ended signals in
    w.saved.mark_clean()                # closing asks nothing: the test's session is dropped
    w.close()
    w.deleteLater()


def scan_recording(qtbot, w):
    ui = w.scan_panel.ui
    ui.sourceCombo.setCurrentIndex(1)
    ui.replayEdit.setText(str(SCAN))
    qtbot.mouseClick(ui.scanButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: w.session.cloud is not None and not w.runner.running("scan"),
                    timeout=WAIT_MS)


def place(qtbot, w, spec='text:"AB"', at=(0.0, 28.0), width=12.0):
    assert w.place_panel.add_pattern(spec)
    w.session.update_selected(at_mm=at, width_mm=width)
    qtbot.waitUntil(lambda: len(w.session.plans) == len(w.session.placements.items)
                    and not w.runner.running("plan") and not w._plan_timer.isActive(),
                    timeout=WAIT_MS)


def fire(qtbot, w):
    """Confirm the armed job: press the arming dialog's Fire button."""
    qtbot.waitUntil(lambda: w.mark_panel.arm_dialog is not None
                    and w.mark_panel.arm_dialog.isVisible(), timeout=WAIT_MS)
    qtbot.mouseClick(w.mark_panel.arm_dialog.fire_button, Qt.LeftButton)


def test_scan_a_recording_shows_progress_frames_and_the_cloud(qtbot, window):
    live = []
    window.session.live_points_added.connect(lambda p: live.append(len(p)))
    scan_recording(qtbot, window)
    ui = window.scan_panel.ui
    assert ui.progressBar.value() == ui.progressBar.maximum() == 27
    expected = services.scan_replay(SCAN, window.session.height_cal)
    assert len(window.session.cloud) == len(expected.cloud)
    assert sum(live) >= len(expected.cloud)          # raw points streamed before filtering
    assert window.view.renderer.points.count == len(expected.cloud)
    assert window.camera_image.image is not None and len(window.camera_image.centres) > 0
    assert f"{len(expected.cloud):,} points" in ui.summaryLabel.text()
    assert ui.scanButton.isEnabled() and not ui.cancelButton.isEnabled()


def test_cancel_a_live_scan(qtbot, window):
    ui = window.scan_panel.ui
    ui.spacingSpin.setValue(0.1)                     # hundreds of lines: time to cancel
    qtbot.mouseClick(ui.scanButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: ui.progressBar.value() >= 1, timeout=WAIT_MS)
    qtbot.mouseClick(ui.cancelButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: not window.runner.running("scan"), timeout=WAIT_MS)
    assert "cancelled" in ui.summaryLabel.text()
    assert ui.progressBar.value() < ui.progressBar.maximum()
    assert window.station.world.laser.kind == "off"
    # the lines measured before the cancel are kept
    cloud = window.session.cloud
    assert cloud is not None and len(cloud) > 0 and "kept" in ui.summaryLabel.text()
    assert len(np.unique(cloud.attributes["line"])) < ui.progressBar.maximum()


def _drag(view, a, b, steps=5):
    a, b = np.asarray(a, float), np.asarray(b, float)
    QTest.mousePress(view, Qt.LeftButton, Qt.NoModifier, QPoint(*a.round().astype(int)))
    for t in np.linspace(0, 1, steps + 1)[1:]:
        QTest.mouseMove(view, QPoint(*(a + t * (b - a)).round().astype(int)))
    QTest.mouseRelease(view, Qt.LeftButton, Qt.NoModifier, QPoint(*b.round().astype(int)))


def test_place_by_dragging_and_turning_then_undo(qtbot, window):
    scan_recording(qtbot, window)
    place(qtbot, window)
    view, s = window.view, window.session
    view.set_view("top")
    centre = view._screen(np.array([0.0, 28.0]), view.handle_z)[0]
    target = centre + (40.0, 0.0)
    expect = view.world_at(*target, view.handle_z)
    steps = len(s.placements._states)
    _drag(view, centre, target)
    assert s.current().at_mm == pytest.approx(tuple(expect), abs=0.05)
    assert s.current().at_mm[0] > 1.0
    assert len(s.placements._states) == steps + 1           # the whole drag: one undo step
    # turn: drag the round handle to the left of the centre → +90°
    rot_px, _ = view._handle_px()
    left = view._screen(np.array(s.current().at_mm) - (10.0, 0.0), view.handle_z)[0]
    _drag(view, rot_px, left)
    assert s.current().rotate_deg == pytest.approx(90.0, abs=1.0)
    assert window.place_panel.ui.rotateSpin.value() == pytest.approx(s.current().rotate_deg)
    # scale: drag the square handle twice as far from the centre → twice as wide
    _, scale_px = view._handle_px()
    c_px = view._screen(np.array(s.current().at_mm), view.handle_z)[0]
    _drag(view, scale_px, c_px + 2 * (scale_px - c_px))
    assert s.current().width_mm == pytest.approx(24.0, rel=0.03)
    window.undo_action.trigger()
    qtbot.waitUntil(lambda: s.plans and s.plans[0].plan is not None
                    and not window._plan_timer.isActive() and not window.runner.running("plan"),
                    timeout=WAIT_MS)
    xy = s.plans[0].plan.projection.points[:, :2]
    assert np.allclose(xy.mean(0), s.current().at_mm, atol=2.0)   # projected where placed
    window.undo_action.trigger()
    assert s.current().rotate_deg == 0.0
    window.undo_action.trigger()
    assert s.current().at_mm == (0.0, 28.0)
    window.redo_action.trigger()
    assert s.current().at_mm == pytest.approx(tuple(expect), abs=0.05)


def test_typed_values_check_and_mark_the_job(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    place(qtbot, window)
    ui = window.place_panel.ui
    ui.hatchCheck.setChecked(True)
    ui.hatchSpin.setValue(0.5)
    ui.widthSpin.setValue(10.0)
    assert window.session.current().hatch_mm == 0.5 and window.session.current().width_mm == 10
    qtbot.waitUntil(lambda: window.session.plans and window.session.plans[0].plan is not None
                    and window.session.plans[0].plan.pattern.size[0] == pytest.approx(10.0)
                    and not window._plan_timer.isActive(), timeout=WAIT_MS)
    assert ui.statusLabel.text().startswith("OK:")
    plan = window.session.plans[0].plan
    job = window.mark_panel.job()
    assert len(job.paths) == len(plan.job.paths) > 10                # hatched
    assert job.laser.power_pct == window.mark_panel.ui.powerSpin.value()
    assert window.save(tmp_path / "m.insitu.json")
    mark = window.mark_panel.ui
    assert mark.markButton.isEnabled() and not mark.abortButton.isEnabled()
    qtbot.mouseClick(mark.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: window.mark_panel.last_result is not None, timeout=WAIT_MS)
    r = window.mark_panel.last_result
    assert (r.state, r.completed, r.total) == ("done", len(job.paths), len(job.paths))
    assert window.station.world.burns and window.station.world.laser.kind == "off"
    # the inspection: the mark read back, rectified onto the cloud with the plan over it
    rb = window.mark_panel.last_readback
    assert rb is not None and len(rb.readings) == 1 and rb.readings[0].offset_mm is not None
    assert window.camera_image.caption == "inspection: in place"
    assert window.camera_image.image.width() == rb.picture.shape[1]
    assert (tmp_path / "m.job.progress.json").exists() and (tmp_path / "m.job.json").exists()
    assert mark.progressBar.value() == len(job.paths)


def test_a_pattern_outside_the_field_is_refused_and_shown(qtbot, window):
    scan_recording(qtbot, window)
    place(qtbot, window, at=(0.0, 60.0), width=12.0)           # beyond the scanned part
    label = window.place_panel.ui.statusLabel
    assert label.text().startswith("refused:") and label.property("warning") is True
    assert "(x, y) = " in label.text() and window.session.plans[0].where[1] > 50.0
    assert window.view.renderer.lines["warnings"][0].count > 0  # red cross where it is
    assert not window.mark_panel.ui.markButton.isEnabled()
    assert window.mark_panel.job() is None


def test_save_and_reopen_the_project(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    place(qtbot, window)
    place(qtbot, window, spec=str(ROOT / "patterns" / "logo.svg"), at=(0.0, -30.0), width=8.0)
    path = tmp_path / "part.insitu.json"
    assert window.save(path)
    other = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(other)
    assert other.recent_files() == [str(path)]
    other.open_project(path)
    qtbot.waitUntil(lambda: other.session.cloud is not None, timeout=WAIT_MS)
    assert other.station is None and "not connected" in other.head_label.text()
    other.connect_action.trigger()                  # the operator connects the project's rig
    qtbot.waitUntil(lambda: other.station is not None, timeout=WAIT_MS)
    s0, s1 = window.session, other.session
    assert np.allclose(s1.cloud.points, s0.cloud.points)
    assert s1.placements.items == s0.placements.items and s1.selected == s0.selected == 1
    assert s1.height_cal_path == s0.height_cal_path and s1.height_cal is not None
    assert other.scan_panel.settings() == window.scan_panel.settings()
    assert not other.undo_action.isEnabled()
    qtbot.waitUntil(lambda: other.session.job() is not None, timeout=WAIT_MS)
    assert other.session.job().digest() == window.session.job().digest()
    other.runner.wait_all()


def test_a_corrupt_project_gives_one_line_and_keeps_the_session(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    bad = tmp_path / "bad.insitu.json"
    bad.write_text('{"format": "insitu-project/1", "schema_version": 1, "cloud": 5}')
    window.open_project(bad)
    qtbot.waitUntil(lambda: not window.runner.running("open"), timeout=WAIT_MS)
    text = window.message_label.full_text()
    assert text.startswith(str(bad)) and "cloud" in text and "\n" not in text
    assert window.session.cloud is not None and window.session.project_path is None


def test_drop_a_pattern_file_and_a_bad_pattern(qtbot, window):
    mime = QMimeData()
    mime.setUrls([QUrl.fromLocalFile(str(ROOT / "patterns" / "part.dxf"))])
    ev = QDropEvent(QPointF(10, 10), Qt.CopyAction, mime, Qt.LeftButton, Qt.NoModifier)
    window.dropEvent(ev)
    assert [p.pattern for p in window.session.placements.items] == [
        str(ROOT / "patterns" / "part.dxf")]
    assert not window.place_panel.add_pattern(str(ROOT / "missing.svg"))
    assert "missing.svg" in window.message_label.full_text()
    assert len(window.session.placements.items) == 1


def test_the_height_calibration_page_shows_residuals_and_a_picture(qtbot, window, tmp_path):
    """The fit's residuals in words and its picture, which a click opens full size."""
    page = window.calibrate_panel.pages["height"]
    page.ui.recordingEdit.setText(str(DATA / "height-cal-b4"))
    page.ui.outputEdit.setText(str(tmp_path / "h.json"))
    qtbot.mouseClick(page.ui.runButton, Qt.LeftButton)
    def done():
        assert page.ui.residualsTable.rowCount() > 0, page.ui.notesLabel.text()
    qtbot.waitUntil(done, timeout=2 * WAIT_MS)          # a fit of 20 planes
    table = page.ui.residualsTable
    rows = {table.item(r, 0).text(): [table.item(r, c).text() for c in range(1, 4)]
            for r in range(table.rowCount())}
    held_out = rows["height error on planes left out of the fit, RMS"]
    assert held_out[0].endswith(" mm") and held_out[1].startswith("pass ≤ 0.05")
    v = float(held_out[0].split()[0])                   # binning 4: coarse, not a failure
    assert v < 0.1 and held_out[2] == page.level == ("pass" if v <= 0.05 else "check")
    assert page.ui.notesLabel.text().startswith(f"height calibration: {page.level}")
    assert not any("_" in name for name in rows)                  # words, not raw names
    assert not page.ui.pictureLabel.pixmap().isNull()
    assert (tmp_path / "h.json").exists()
    qtbot.waitUntil(lambda: window.session.height_cal_path == tmp_path / "h.json",
                    timeout=WAIT_MS)
    # a click on the picture opens it full size, zoomed by the keys
    shown = page.ui.pictureLabel.pixmap()
    qtbot.mouseClick(page.ui.pictureLabel, Qt.LeftButton)
    win = page.picture_window
    assert win is not None and win.isVisible()
    full = win.view.image
    h, w = cv2.imread(str(tmp_path / "h.png")).shape[:2]
    assert (full.width(), full.height()) == (w, h) and full.width() > shown.width()
    win.view.to_widget(np.zeros((1, 2)))              # the fitted scale, at the window's size
    z0 = win.view.scale
    assert win.view.fitted and z0 < 1.0
    QTest.keyClick(win.view, Qt.Key_Plus)
    assert win.view.scale == pytest.approx(z0 * 1.25) and not win.view.fitted
    QTest.keyClick(win.view, Qt.Key_1)
    assert win.view.scale == pytest.approx(1.0)
    QTest.keyClick(win.view, Qt.Key_0)
    assert win.view.fitted


def test_a_device_fault_mid_scan_keeps_what_was_measured(qtbot, window, monkeypatch):
    from insitu.errors import DeviceError
    from insitu.sim.devices import SimCamera

    grab, calls = SimCamera.grab, []

    def failing_grab(self, *a, **k):
        calls.append(1)
        if len(calls) > 8:
            raise DeviceError("camera: frame timed out")
        return grab(self, *a, **k)

    monkeypatch.setattr(SimCamera, "grab", failing_grab)
    qtbot.mouseClick(window.scan_panel.ui.scanButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: not window.runner.running("scan"), timeout=WAIT_MS)
    text = window.scan_panel.ui.summaryLabel.text()
    assert "camera: frame timed out" in text and "kept" in text
    assert window.session.cloud is not None and len(window.session.cloud) > 100
    assert window.station.world.laser.kind == "off"
    assert window.message_label.full_text() == text


def test_a_mark_in_a_codes_quiet_zone_is_refused_where_it_is_placed(qtbot, window):
    scan_recording(qtbot, window)
    place(qtbot, window, spec='qr:"insitu"', at=(0.0, 28.0), width=10.5)   # 0.5 mm modules
    code_hatch = window.session.current().hatch_mm
    place(qtbot, window, spec='text:"A"', at=(8.5, 28.0), width=3.0)   # in its 2 mm zone
    label, s = window.place_panel.ui.statusLabel, window.session
    assert s.selected == 1 and label.property("warning") is True
    assert label.text().startswith("refused: text:A: its marks enter the quiet zone of "
                                   "placement 1 (qr:insitu)")
    assert "placement 2's marks enter its quiet zone" in s.plans[0].error
    assert window.view.renderer.lines["warnings"][0].count > 0   # the red cross
    s.update_selected(at_mm=(9.5, 28.0))                         # moved clear of it
    qtbot.waitUntil(lambda: len(s.plans) == 2 and not window.runner.running("plan")
                    and not window._plan_timer.isActive(), timeout=WAIT_MS)
    assert all(o.plan for o in s.plans), [o.error for o in s.plans]
    assert label.text().startswith("OK:")
    s.select(0)
    s.update_selected(width_mm=6.3)                              # 0.3 mm modules
    assert s.current().hatch_mm == pytest.approx(0.05) == code_hatch
    s.update_selected(width_mm=4.62)                             # 0.22 mm: 5 lines each
    assert s.current().hatch_mm == pytest.approx(0.044)


def test_pilot_preview_then_abort_stops_mid_job(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    place(qtbot, window, spec='qr:"insitu"', at=(0.0, 28.0), width=10.1)  # the symbol
    assert 0 < window.session.placements.items[-1].hatch_mm <= 0.05   # a code: hatched
    window.session.update_selected(hatch_mm=0.03)
    qtbot.waitUntil(lambda: window.mark_panel.job() is not None
                    and len(window.mark_panel.job().paths) > 100
                    and not window._plan_timer.isActive()
                    and not window.runner.running("plan"), timeout=WAIT_MS)
    mark, world = window.mark_panel.ui, window.station.world
    qtbot.mouseClick(mark.previewButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: window.view.renderer.lines.get("pilot", (None,))[0] is not None
                    and window.view.renderer.lines["pilot"][0].count > 0, timeout=WAIT_MS)
    assert not world.burns and world.laser.kind == "off"      # the pilot burns nothing
    assert window.save(tmp_path / "a.insitu.json")
    total = len(window.mark_panel.job().paths)
    qtbot.waitUntil(mark.markButton.isEnabled, timeout=WAIT_MS)     # the preview has ended
    qtbot.mouseClick(mark.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: mark.progressBar.value() >= 5, timeout=WAIT_MS)
    assert mark.abortButton.isEnabled() and "left" in mark.timeLabel.text()
    qtbot.mouseClick(mark.abortButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: not window.runner.running("mark"), timeout=WAIT_MS)
    # stopped mid-path ("aborted", the path not counted) or between paths ("cancelled")
    text = mark.resultLabel.text()
    assert ("aborted" in text or text.startswith("cancelled")) and "laser is off" in text
    assert world.laser.kind == "off"
    record = json.loads((tmp_path / "a.job.progress.json").read_text())
    assert record["state"] in ("interrupted", "cancelled") and 5 <= record["completed"] < total
    assert not mark.abortButton.isEnabled() and mark.markButton.isEnabled()


def test_variable_data_previews_the_next_serial_and_marking_takes_it(qtbot, window, tmp_path):
    from insitu.formats.counter import locked, read_counter
    from insitu.marking import read_job

    scan_recording(qtbot, window)
    place(qtbot, window, 'qr:"SN{serial:04d}";ec=H', width=8.0)
    mark = window.mark_panel.ui
    qtbot.waitUntil(lambda: window.mark_panel.job() is not None, timeout=WAIT_MS)
    assert window.session.plans[0].plan.pattern.code.text == "SN0001"   # no counter yet
    assert window.save(tmp_path / "m.insitu.json")
    assert not (tmp_path / "m.job.json").exists()             # written when marked, not saved
    qtbot.waitUntil(mark.markButton.isEnabled, timeout=WAIT_MS)
    window.mark_panel.mark()                                          # refused: no counter
    fire(qtbot, window)
    def refused():
        assert "no serial counter" in mark.resultLabel.text(), mark.resultLabel.text()
    qtbot.waitUntil(refused, timeout=WAIT_MS)
    assert window.mark_panel.last_result is None
    counter = tmp_path / "serial.counter.json"
    with locked(counter) as c:
        c.create(5)
    window.mark_panel.refresh()
    assert "serial 5 shown as a preview (taken when marked)" in mark.jobLabel.text()
    for serial in (5, 6):
        window.mark_panel.last_result = None
        qtbot.waitUntil(lambda: mark.markButton.isEnabled()
                        and not window.runner.running("mark"), timeout=WAIT_MS)
        window.mark_panel.mark()
        fire(qtbot, window)
        def marked():
            assert window.mark_panel.last_result is not None, mark.resultLabel.text()
        qtbot.waitUntil(marked, timeout=3 * WAIT_MS)     # marked, imaged, read back
        assert window.mark_panel.last_result.state == "done"
        rec = read_job(tmp_path / "m.job.json").model_extra["variable_data"]
        assert rec["serial"] == serial and rec["texts"][0]["text"] == f"SN{serial:04d}"
    assert read_counter(counter).next == 7
