"""The operator's station as a professional expects it (pytest-qt, offscreen, real widgets):
Mark arms and waits for a confirmation, Resume after an abort, quitting asks to save, clouds
and jobs made by the commands open, File ▸ Export job, the Help menu, refusals shown where
they happen and cleared when they no longer hold, Ctrl+Z in a field."""

import numpy as np
import pytest
import test_gui_workflow as wf
from PySide6.QtCore import QMimeData, QPointF, QSettings, Qt, QTimer, QUrl
from PySide6.QtGui import QAction, QDropEvent, QKeySequence
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication, QMessageBox
from test_gui_workflow import DATA, WAIT_MS, fire, place, scan_recording

from insitu.formats.pointcloud import write_ply
from insitu.marking import journal_path_for, read_job
from insitu.services.serials import save_job
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.scan_panel import NO_RIG

window = wf.window       # the workflow tests' fixture


def answer_box(button, seen=None, after_ms=50, tries=400):
    """Press ``button`` (a StandardButton, or a button's text) in the next message box that
    opens (within ``tries`` × ``after_ms``); its text goes to ``seen``."""
    def click(left=tries):
        boxes = [w for w in QApplication.topLevelWidgets()
                 if isinstance(w, QMessageBox) and w.isVisible()]
        if not boxes:
            if left:
                QTimer.singleShot(after_ms, lambda: click(left - 1))
            return
        box = boxes[0]
        if seen is not None:
            seen.append(box.text())
        if isinstance(button, str):
            found = [b for b in box.buttons() if b.text().replace("&", "") == button]
        else:
            found = [box.button(button)]
        (found[0] if found and found[0] is not None else box.buttons()[-1]).click()
    QTimer.singleShot(after_ms, click)


SAVE, DISCARD, CANCEL = (QMessageBox.StandardButton.Save, QMessageBox.StandardButton.Discard,
                         QMessageBox.StandardButton.Cancel)


def planned(qtbot, w):
    qtbot.waitUntil(lambda: len(w.session.plans) == len(w.session.placements.items)
                    and not w.runner.running("plan") and not w._plan_timer.isActive(),
                    timeout=WAIT_MS)


# -- 1. arm and confirm -------------------------------------------------------------------
def test_mark_arms_shows_the_job_and_fires_only_when_confirmed(qtbot, window):
    scan_recording(qtbot, window)
    place(qtbot, window)
    mark, world = window.mark_panel.ui, window.station.world
    qtbot.mouseClick(mark.previewButton, Qt.LeftButton)        # the pilot needs no arming
    qtbot.waitUntil(lambda: not window.runner.running("preview"), timeout=WAIT_MS)
    assert "pilot preview" in window.message_label.full_text()
    qtbot.mouseClick(mark.markButton, Qt.LeftButton)
    dlg = window.mark_panel.arm_dialog
    qtbot.waitUntil(lambda: dlg.isVisible(), timeout=WAIT_MS)
    rows = dict(dlg.rows)
    job = window.mark_panel.job()
    assert rows["patterns"] == 'text:"AB"' and rows["paths"] == str(len(job.paths))
    assert {"marked length", "extent, mm", "time", "laser", "planned on", "station"} <= set(rows)
    assert "30 %" in rows["laser"] and rows["planned on"] == "not recorded"   # a replay
    assert rows["station"] == " · ".join(window.station.describe())
    assert not world.burns and not window.runner.running("mark")    # nothing sent yet
    assert not mark.markButton.isEnabled() and "armed" in mark.resultLabel.text()
    QTest.keyClick(dlg, Qt.Key_Escape)                              # Esc disarms
    qtbot.waitUntil(lambda: not dlg.isVisible(), timeout=WAIT_MS)
    assert window.mark_panel.arm_dialog is None and mark.markButton.isEnabled()
    assert "disarmed" in mark.resultLabel.text() and not world.burns
    QTest.qWait(200)
    assert not window.runner.running("mark") and not world.burns
    qtbot.mouseClick(mark.markButton, Qt.LeftButton)                # armed again …
    qtbot.waitUntil(lambda: window.mark_panel.arm_dialog is not None, timeout=WAIT_MS)
    window.session.update_selected(at_mm=(1.0, 28.0))               # … the job changes
    qtbot.waitUntil(lambda: window.mark_panel.arm_dialog is None, timeout=WAIT_MS)
    assert "disarmed: the job changed" in mark.resultLabel.text() and not world.burns
    planned(qtbot, window)
    qtbot.mouseClick(mark.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: window.mark_panel.last_result is not None, timeout=WAIT_MS)
    assert window.mark_panel.last_result.state == "done" and world.burns


# -- 2. resume ----------------------------------------------------------------------------
def test_resume_after_a_fault_marks_the_rest(qtbot, window, tmp_path, monkeypatch):
    from insitu.errors import DeviceError
    from insitu.sim.controller import SimController

    scan_recording(qtbot, window)
    place(qtbot, window)
    mark, panel = window.mark_panel.ui, window.mark_panel
    assert window.save(tmp_path / "r.insitu.json")
    assert not panel.resume_button.isEnabled()                      # nothing unfinished
    total = len(panel.job().paths)
    execute, calls = SimController.execute, []

    def failing(self, commands):
        calls.append(1)
        if len(calls) == 4:
            raise DeviceError("scan head: list timed out")
        return execute(self, commands)

    monkeypatch.setattr(SimController, "execute", failing)
    qtbot.mouseClick(mark.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: "timed out" in mark.resultLabel.text(), timeout=WAIT_MS)
    qtbot.waitUntil(panel.resume_button.isEnabled, timeout=WAIT_MS)  # the journal: unfinished
    offered = []
    answer_box("Mark the cut path again", offered)
    qtbot.mouseClick(panel.resume_button, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: panel.last_result is not None and not window.runner.running("mark"),
                    timeout=WAIT_MS)
    r = panel.last_result
    assert (r.state, r.completed, r.total) == ("done", total, total) and r.start_path == 3
    assert offered and "interrupted after 3 of" in offered[0]
    assert not panel.resume_button.isEnabled()                      # finished


# -- 3. unsaved changes -------------------------------------------------------------------
def test_quit_asks_to_save_a_placement(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    place(qtbot, window)
    assert window.save(tmp_path / "q.insitu.json")
    assert not window.saved.dirty()
    window.session.update_selected(at_mm=(2.0, 28.0))
    assert window.saved.changes() == ["placements"]
    seen = []
    answer_box(CANCEL, seen)
    assert window.quit_action.shortcut() == QKeySequence("Ctrl+Q")
    window.quit_action.trigger()                                    # Ctrl+Q
    qtbot.waitUntil(lambda: bool(seen), timeout=WAIT_MS)
    assert window.isVisible() and window.session.current().at_mm == (2.0, 28.0)
    assert "placements" in seen[0]
    answer_box(SAVE)
    assert window.close()
    from insitu.formats.project import read_project
    from insitu.marking import PROJECTIONS, Placement
    saved = read_project(tmp_path / "q.insitu.json", Placement, PROJECTIONS)
    assert saved.placements[0].at_mm == (2.0, 28.0)


def test_discard_new_and_nothing_to_ask(qtbot, window):
    place(qtbot, window)
    answer_box(CANCEL)
    window.new_project()                                            # New asks too
    assert window.session.placements.items
    answer_box(DISCARD)
    window.new_project()
    assert not window.session.placements.items and not window.saved.dirty()
    assert window.close()                                           # nothing unsaved: no box


def test_quit_while_marking_asks_to_abort_first(qtbot, window):
    scan_recording(qtbot, window)
    place(qtbot, window, spec='qr:"insitu"', at=(0.0, 28.0), width=10.1)
    window.session.update_selected(hatch_mm=0.03)
    qtbot.waitUntil(lambda: window.mark_panel.job() is not None
                    and len(window.mark_panel.job().paths) > 100
                    and not window._plan_timer.isActive()
                    and not window.runner.running("plan"), timeout=WAIT_MS)
    qtbot.mouseClick(window.mark_panel.ui.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: window.mark_panel.ui.progressBar.value() >= 2, timeout=WAIT_MS)
    answer_box(CANCEL)
    assert not window.close() and window.runner.running("mark")     # refused: still marking
    answer_box("Abort and quit")
    answer_box(DISCARD, after_ms=300)
    assert window.close()
    assert not window.runner.running("mark") and window.station.world.laser.kind == "off"


# -- 4. clouds and jobs of the commands ---------------------------------------------------
def test_open_a_cloud_a_job_and_export(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    cloud = window.session.cloud
    write_ply(tmp_path / "part.ply", cloud)
    window.new_project() if not window.saved.dirty() else None
    window.saved.mark_clean()
    window.session.set_cloud(None)
    window.saved.mark_clean()
    mime = QMimeData()
    mime.setUrls([QUrl.fromLocalFile(str(tmp_path / "part.ply"))])    # drag and drop
    window.dropEvent(QDropEvent(QPointF(10, 10), Qt.CopyAction, mime, Qt.LeftButton,
                                Qt.NoModifier))
    qtbot.waitUntil(lambda: window.session.cloud is not None, timeout=WAIT_MS)
    assert np.allclose(window.session.cloud.points, cloud.points)
    assert window.session.cloud_path == tmp_path / "part.ply"
    assert str(tmp_path / "part.ply") in window.recent_files()
    place(qtbot, window)
    job_file = tmp_path / "exported.json"
    assert window.save(tmp_path / "e.insitu.json")
    from insitu.ui.qt import open_files
    assert open_files.export_job(window, job_file)                  # File ▸ Export job
    exported = read_job(job_file)
    assert exported.digest() == window.mark_panel.job().digest()
    window.open_file(job_file)                                      # a job made elsewhere
    qtbot.waitUntil(lambda: window.session.job_file is not None, timeout=WAIT_MS)
    assert not window.session.placements.items
    assert window.view.renderer.lines["job"][0].count == 2 * sum(
        len(p.points) - 1 for p in exported.paths)
    assert window.mark_panel.ui.jobLabel.text().startswith("job file exported.json")
    window.mark_panel.ui.powerSpin.setValue(55.0)                   # the file's laser counts
    assert window.mark_panel.job().laser == exported.laser
    qtbot.waitUntil(window.mark_panel.ui.markButton.isEnabled, timeout=WAIT_MS)
    qtbot.mouseClick(window.mark_panel.ui.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: window.mark_panel.last_result is not None, timeout=WAIT_MS)
    assert window.mark_panel.last_result.state == "done"
    assert journal_path_for(job_file).exists()                      # as insitu job run
    assert read_job(job_file).digest() == exported.digest()        # the file left as it is


@pytest.mark.qt_no_exception_capture   # offscreen Qt paints the 3-D view once here, no GL
def test_a_job_for_another_workpiece_is_refused(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    place(qtbot, window)
    job = window.mark_panel.job().model_copy(update={"rig": {"workpiece": "arc", "seed": 0,
                                                             "binning": 4}})
    save_job(tmp_path / "arc.json", job)
    window.saved.mark_clean()
    window.open_file(tmp_path / "arc.json")
    qtbot.waitUntil(lambda: window.session.job_file is not None, timeout=WAIT_MS)
    qtbot.waitUntil(window.mark_panel.ui.markButton.isEnabled, timeout=WAIT_MS)
    qtbot.mouseClick(window.mark_panel.ui.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: not window.runner.running("mark")
                    and "arc" in window.mark_panel.ui.resultLabel.text(), timeout=WAIT_MS)
    assert window.mark_panel.last_result is None and not window.station.world.burns


def test_insitu_mark_writes_a_project_the_gui_opens(qtbot, tmp_path):
    from typer.testing import CliRunner

    from insitu import services
    from insitu.cli.main import app

    cloud = services.scan_replay(DATA / "scan-step-block-b4").cloud
    write_ply(tmp_path / "c.ply", cloud)
    res = CliRunner().invoke(app, ["mark", "--cloud", str(tmp_path / "c.ply"), "--pattern",
                                   'text:"AB"', "--at", "0", "28", "--width", "12", "-o",
                                   str(tmp_path / "job.json"), "--project",
                                   str(tmp_path / "p.insitu.json")])
    assert res.exit_code == 0, res.output
    bad = CliRunner().invoke(app, ["mark", "--cloud", str(tmp_path / "c.ply"), "--pattern",
                                   'text:"AB"', "--at", "0", "28", "-o",
                                   str(tmp_path / "other.json"), "--project",
                                   str(tmp_path / "p.json")])
    assert isinstance(bad.exception, SystemExit) and bad.exit_code == 1
    assert "expected a *.insitu.json file name" in bad.output
    assert not (tmp_path / "other.json").exists()                   # refused before planning
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(w)
    w.open_project(tmp_path / "p.insitu.json")
    qtbot.waitUntil(lambda: w.session.cloud is not None, timeout=WAIT_MS)
    p = w.session.placements.items[0]
    assert (p.pattern, p.at_mm, p.width_mm) == ('text:"AB"', (0.0, 28.0), 12.0)
    assert len(w.session.cloud) == len(cloud) and w.session.cloud_path == tmp_path / "c.ply"
    assert not w.saved.dirty()
    w.runner.wait_all()


# -- 5. help ------------------------------------------------------------------------------
def test_help_menu_guide_shortcuts_and_about(qtbot, window):
    window.guide_action.trigger()
    guide = window.help_windows["guide"]
    assert guide.isVisible() and guide.path is not None
    assert "Every part" in guide.browser.toPlainText()
    extra = QAction("Test action", window)
    extra.setShortcut(QKeySequence("Ctrl+Alt+T"))
    window.addAction(extra)
    window.shortcuts_action.trigger()
    table = window.help_windows["shortcuts"].table
    rows = {table.item(r, 0).text(): table.item(r, 1).text() for r in range(table.rowCount())}
    native = QKeySequence.SequenceFormat.NativeText
    assert rows["Undo"] == QKeySequence(QKeySequence.StandardKey.Undo).toString(native)
    assert rows["Quit"] == QKeySequence("Ctrl+Q").toString(native)
    assert rows["Test action"] == QKeySequence("Ctrl+Alt+T").toString(native)
    assert rows["Top view"] == "1"
    with_keys = {a.text().replace("&", "").rstrip("…") for a in window.findChildren(QAction)
                 if not a.shortcut().isEmpty()}
    assert set(rows) == with_keys
    window.about_action.trigger()
    about = window.help_windows["about"]
    assert about.isVisible()
    from PySide6.QtCore import qVersion

    import insitu
    assert insitu.__version__ in about.text() and qVersion() in about.text()
    assert "OpenGL" in about.text()


def test_the_guide_window_says_when_the_guide_is_absent(qtbot, monkeypatch, tmp_path):
    from insitu.ui.qt import help as help_mod
    monkeypatch.setattr(help_mod, "guide_candidates", lambda: [tmp_path / "none.md"])
    g = help_mod.GuideWindow()
    qtbot.addWidget(g)
    assert g.path is None and "not installed" in g.browser.toPlainText()
    assert str(tmp_path / "none.md") in g.browser.toPlainText()


# -- 6. refusals where they happen, cleared when they no longer hold ----------------------
def test_a_refusal_on_its_row_and_in_the_status_bar_then_cleared(qtbot, window, tmp_path):
    scan_recording(qtbot, window)
    place(qtbot, window)
    assert window.save(tmp_path / "s.insitu.json")
    mark = window.mark_panel.ui
    qtbot.mouseClick(mark.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: window.mark_panel.last_result is not None, timeout=WAIT_MS)
    assert mark.resultLabel.text().startswith("done: paths")
    window.session.update_selected(at_mm=(0.0, 60.0))               # now refused
    planned(qtbot, window)
    item = window.place_panel.ui.patternList.item(0)
    assert item.toolTip().startswith("refused:") and item.foreground().color().red() > 200
    assert item.foreground().color().green() < 150
    assert window.message_label.full_text().startswith("placement 1 refused:")
    assert mark.resultLabel.text() == "" and mark.timeLabel.text() == ""   # not "done: …"
    assert "refused" in mark.jobLabel.text()
    window.session.update_selected(at_mm=(0.0, 28.0))               # OK again
    planned(qtbot, window)
    item = window.place_panel.ui.patternList.item(0)
    assert window.message_label.full_text() == "" and item.toolTip() == ""


def test_scan_and_the_status_bar_agree_on_the_rig(qtbot, tmp_path):
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(w)
    ui = w.scan_panel.ui
    assert not ui.scanButton.isEnabled() and ui.scanButton.toolTip() == NO_RIG
    ui.summaryLabel.setText(NO_RIG)
    ui.sourceCombo.setCurrentIndex(1)                               # a recording needs none
    assert ui.scanButton.isEnabled()
    ui.sourceCombo.setCurrentIndex(0)
    from insitu.formats.project import RigChoice
    w.connect_rig(RigChoice(binning=4))
    qtbot.waitUntil(lambda: w.station is not None, timeout=WAIT_MS)
    assert w.message_label.full_text() == "rig connected" and ui.scanButton.isEnabled()
    assert ui.summaryLabel.text() == ""                             # no "connect the rig first"
    w.disconnect_rig()
    assert w.message_label.full_text() == "" and not ui.scanButton.isEnabled()
    w.runner.wait_all()


# -- 7. undo while a field has focus ------------------------------------------------------
def test_ctrl_z_in_a_field_undoes_the_placement(qtbot, window):
    place(qtbot, window, width=12.0)
    spin = window.place_panel.ui.widthSpin
    spin.setFocus()
    qtbot.waitUntil(spin.hasFocus, timeout=WAIT_MS)
    spin.selectAll()
    QTest.keyClicks(spin, "15")
    QTest.keyClick(spin, Qt.Key_Return)
    assert window.session.current().width_mm == 15.0
    QTest.keySequence(spin, QKeySequence.StandardKey.Undo)
    assert window.session.current().width_mm == 12.0 and spin.value() == 12.0
    QTest.keySequence(spin, QKeySequence.StandardKey.Redo)
    assert window.session.current().width_mm == 15.0 and spin.value() == 15.0
    spin.selectAll()
    QTest.keyClicks(spin, "9")                                      # typed, not committed
    QTest.keySequence(spin, QKeySequence.StandardKey.Undo)
    assert window.session.current().width_mm == 12.0
    assert spin.value() == 12.0 and spin.text().startswith("12")
