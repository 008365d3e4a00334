"""What operators of other laser stations expect (pytest-qt, offscreen): keys go to the 3-D
view unless a field is being edited, Esc reverts a field, arrows nudge the selected pattern,
F1 / F2 / Esc for Preview / Mark / ABORT listed in Help; a rescan that is cancelled or fails
keeps the cloud the operator had."""

import pytest
import test_gui_workflow as wf
from PySide6.QtCore import QPoint, Qt
from PySide6.QtTest import QTest
from test_gui_workflow import WAIT_MS, scan_recording

from insitu.errors import DeviceError
from insitu.sim.devices import SimCamera

window = wf.window


def focus(qtbot, widget) -> None:
    widget.window().activateWindow()
    widget.setFocus()
    qtbot.waitUntil(widget.hasFocus, timeout=WAIT_MS)


def test_keys_go_to_the_view_unless_a_field_is_edited_shortcut_focus(qtbot, window):
    assert window.place_panel.add_pattern('text:"AB"')
    ui, view, s = window.place_panel.ui, window.view, window.session
    x0, y0 = s.current().at_mm
    view.set_view("iso")
    focus(qtbot, ui.rotateSpin)                     # typed into the field: the field's
    ui.rotateSpin.selectAll()
    QTest.keyClicks(ui.rotateSpin, "15")
    assert not view.camera.ortho
    QTest.keyClick(ui.rotateSpin, Qt.Key_Return)
    assert s.current().rotate_deg == 15.0
    qtbot.waitUntil(view.hasFocus, timeout=WAIT_MS)  # committed: the keys are the view's
    QTest.keyClick(view, Qt.Key_1)
    assert view.camera.ortho and s.current().rotate_deg == 15.0
    assert ui.rotateSpin.text().startswith("15")

    focus(qtbot, ui.xSpin)                          # Esc reverts what was typed
    ui.xSpin.selectAll()
    QTest.keyClicks(ui.xSpin, "20")
    QTest.keyClick(ui.xSpin, Qt.Key_Escape)
    assert s.current().at_mm == (x0, y0) and ui.xSpin.value() == pytest.approx(x0)
    assert ui.xSpin.text().replace(",", ".").startswith(f"{x0:.1f}")
    assert view.hasFocus()

    focus(qtbot, ui.ySpin)                          # a click in the view takes the keys
    corner = QPoint(5, view.height() - 5)
    QTest.mouseClick(view, Qt.LeftButton, Qt.NoModifier, corner)
    assert view.hasFocus()
    QTest.keyClick(view, Qt.Key_Right)              # arrows nudge, Shift ×10
    QTest.keyClick(view, Qt.Key_Up, Qt.ShiftModifier)
    x, y = s.current().at_mm
    assert (x, y) == (pytest.approx(x0 + 0.1), pytest.approx(y0 + 1.0))

    fired = []
    for name in ("preview_action", "mark_action"):
        getattr(window.mark_panel, name).triggered.connect(lambda _=False, n=name:
                                                           fired.append(n))
    window.mark_panel.preview_action.setEnabled(True)
    window.mark_panel.mark_action.setEnabled(True)
    QTest.keyClick(view, Qt.Key_F1)
    QTest.keyClick(view, Qt.Key_F2)
    assert fired == ["preview_action", "mark_action"]

    window.shortcuts_action.trigger()               # listed in Help
    table = window.help_windows["shortcuts"].table
    rows = {table.item(r, 0).text(): table.item(r, 1).text() for r in range(table.rowCount())}
    assert rows["Preview (red light)"] == "F1" and rows["Mark"] == "F2"
    assert rows["ABORT"] == "Esc, Space"
    assert rows["Nudge the pattern right 0.1 mm"] == "Right"


def test_a_cancelled_or_failed_rescan_keeps_the_cloud_rescan_cancel(qtbot, window,
                                                                    monkeypatch):
    scan_recording(qtbot, window)
    good, panel = window.session.cloud, window.scan_panel
    ui = panel.ui
    n = len(good)
    ui.sourceCombo.setCurrentIndex(0)                   # the rig, lines 0.1 mm apart
    ui.spacingSpin.setValue(0.1)

    grab, calls = SimCamera.grab, []

    def failing_grab(self, *a, **k):
        calls.append(1)
        if len(calls) > 6:
            raise DeviceError("camera: frame timed out")
        return grab(self, *a, **k)

    monkeypatch.setattr(SimCamera, "grab", failing_grab)
    qtbot.mouseClick(ui.scanButton, Qt.LeftButton)      # fails
    qtbot.waitUntil(lambda: not window.runner.running("scan"), timeout=WAIT_MS)
    assert "frame timed out" in ui.summaryLabel.text()
    assert window.session.cloud is good and window.view.renderer.points.count == n
    monkeypatch.undo()

    qtbot.mouseClick(ui.scanButton, Qt.LeftButton)      # cancelled
    qtbot.waitUntil(lambda: ui.progressBar.value() >= 2, timeout=WAIT_MS)
    qtbot.mouseClick(ui.cancelButton, Qt.LeftButton)
    qtbot.waitUntil(lambda: not window.runner.running("scan"), timeout=WAIT_MS)
    assert "cancelled" in ui.summaryLabel.text()
    assert window.session.cloud is good and window.view.renderer.points.count == n
    assert panel.partial_button.isVisible()             # the partial one: beside it
    partial = panel.partial.cloud
    assert len(partial) > 0 and f"{len(partial):,} points" in panel.partial_button.text()

    qtbot.mouseClick(panel.partial_button, Qt.LeftButton)
    assert window.session.cloud is partial and not panel.partial_button.isVisible()
    window.undo_action.trigger()                        # and Undo brings the good one back
    assert window.session.cloud is good and window.view.renderer.points.count == n


def test_a_picture_window_closes_with_esc_or_its_close_button(qtbot):
    from PySide6.QtGui import QPixmap
    from PySide6.QtWidgets import QDialogButtonBox

    from insitu.ui.qt.image_window import ImageWindow

    pix = QPixmap(64, 48)
    pix.fill(Qt.gray)
    for close in ("esc", "button"):
        win = ImageWindow(pix, "report", None)
        qtbot.addWidget(win)
        win.show()
        qtbot.waitExposed(win)
        win.view.setFocus()
        if close == "esc":
            QTest.keyClick(win.view, Qt.Key_Escape)
        else:
            qtbot.mouseClick(win.buttons.button(QDialogButtonBox.StandardButton.Close),
                             Qt.LeftButton)
        assert not win.isVisible(), close


def test_the_height_page_records_on_the_rig_and_cancel_stops_it(qtbot, window, tmp_path):
    page = window.calibrate_panel.pages["height"]
    assert not window.calibrate_panel.pages["camera"].record_button.isEnabled()
    folder = tmp_path / "rec"
    page.ui.recordingEdit.setText(str(folder))
    qtbot.mouseClick(page.record_button, Qt.LeftButton)
    qtbot.waitUntil(lambda: page.ui.progressBar.value() >= 2, timeout=WAIT_MS)
    assert page.cancel_button.isEnabled() and not page.record_button.isEnabled()
    qtbot.mouseClick(page.cancel_button, Qt.LeftButton)
    qtbot.waitUntil(lambda: not window.runner.running(page.record_name), timeout=WAIT_MS)
    assert "recording cancelled" in page.ui.notesLabel.text() and not folder.exists()
    world = window.station.world
    assert world.laser.kind == "off" and world.parts            # the part back on the table
    assert page.record_button.isEnabled() and not page.cancel_button.isEnabled()
