"""A project never saved keeps its jobs' journals in the working folder from the first
"started": after ABORT, and after the application was killed, Resume finishes the job and no
path is marked twice — counted on the simulated board itself (every mark it executes)."""

import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import test_gui_workflow as wf
from PySide6.QtCore import QSettings, Qt
from PySide6.QtWidgets import QApplication, QMessageBox
from test_gui_workflow import DATA, WAIT_MS, fire, place, scan_recording

from insitu.devices.galvo import list_digest
from insitu.marking import journal_path_for, read_job, read_journal
from insitu.sim.controller import MARK_LOG_ENV, SimController
from insitu.ui.model.session import RigChoice
from insitu.ui.qt.main_window import MainWindow

window = wf.window
SRC = Path(__file__).parents[2] / "src"
PATTERN = dict(spec='text:"AB"', at=(0.0, 28.0), width=12.0)
HATCH_MM = 0.5                  # 53 paths: long enough to stop, short enough to finish


def segments(commands, done: int | None = None) -> list[tuple]:
    """The mark moves (from, to) of a list's first ``done`` commands (all: None)."""
    out, at = [], None
    for c in commands[:done]:
        if c.op in ("jump_abs_3d", "mark_abs_3d"):
            to = tuple(np.round(np.asarray(c.args, float), 6))
            if c.op == "mark_abs_3d":
                out.append((at, to))
            at = to
    return out


class Board:
    """What the simulated board executes, mark by mark (a slow board: 2 ms a command, so
    that ABORT lands within a path)."""

    def __init__(self, monkeypatch):
        self.marked: Counter = Counter()
        execute, do = SimController.execute, SimController._do

        def slow(controller, command):
            time.sleep(0.002)
            do(controller, command)

        def counted(controller, commands):
            try:
                execute(controller, commands)
            finally:
                pos = controller.position()
                done = pos.done if pos is not None and pos.digest == list_digest(commands) \
                    else len(commands)
                self.marked.update(segments(commands, done))
        monkeypatch.setattr(SimController, "execute", counted)
        monkeypatch.setattr(SimController, "_do", slow)


def answer(choice_texts):
    """Press the first of ``choice_texts`` offered by the next question box."""
    from PySide6.QtCore import QTimer

    def click(left=400):
        boxes = [w for w in QApplication.topLevelWidgets()
                 if isinstance(w, QMessageBox) and w.isVisible()]
        if not boxes:
            if left:
                QTimer.singleShot(50, lambda: click(left - 1))
            return
        buttons = {b.text().replace("&", ""): b for b in boxes[0].buttons()}
        next(buttons[t] for t in choice_texts if t in buttons).click()
    QTimer.singleShot(50, click)


def every_segment(window, job) -> Counter:
    return Counter(s for cmds in window.station.driver.compile(job) for s in segments(cmds))


def test_no_path_marked_twice_after_abort_unsaved(qtbot, window, monkeypatch):
    board = Board(monkeypatch)
    scan_recording(qtbot, window)
    place(qtbot, window, **PATTERN)
    window.session.update_selected(hatch_mm=HATCH_MM)
    wf_planned = lambda: (len(window.session.plans) == 1 and not window.runner.running("plan")
                          and not window._plan_timer.isActive())
    qtbot.waitUntil(wf_planned, timeout=WAIT_MS)
    assert window.session.project_path is None                     # never saved
    panel, ui = window.mark_panel, window.mark_panel.ui
    job = panel.job()
    qtbot.mouseClick(ui.markButton, Qt.LeftButton)
    fire(qtbot, window)
    qtbot.waitUntil(lambda: ui.progressBar.value() >= 3, timeout=WAIT_MS)
    qtbot.mouseClick(ui.abortButton, Qt.LeftButton)                 # ABORT
    qtbot.waitUntil(lambda: not window.runner.running("mark"), timeout=WAIT_MS)
    qtbot.waitUntil(panel.resume_button.isEnabled, timeout=WAIT_MS)   # the journal: unfinished
    work = window.work_folder()
    s = read_journal(journal_path_for(panel.job_path()))
    assert panel.job_path().parent == work
    assert s is not None and 3 <= len(s.done) < len(job.paths)
    assert str(work) in window.journal_label.toolTip()             # named in the status bar
    answer(["Continue the cut path", "Resume"])
    qtbot.mouseClick(panel.resume_button, Qt.LeftButton)
    qtbot.waitUntil(lambda: panel.arm_dialog is not None, timeout=WAIT_MS)
    rows = dict(panel.arm_dialog.rows)
    assert rows["job file"].startswith(str(work)) and "working folder" in rows["journal"]
    panel.last_result = None
    fire(qtbot, window)

    def finished():
        assert panel.last_result is not None and not window.runner.running("mark"), \
            ui.resultLabel.text()
    qtbot.waitUntil(finished, timeout=WAIT_MS)
    r = panel.last_result
    assert r.state == "done" and r.cut is not None and r.cut_choice == "continue"
    assert max(board.marked.values()) == 1                          # no mark twice
    assert set(board.marked) == set(every_segment(window, job))     # and none left out
    assert not panel.resume_button.isEnabled()


APP = """
import sys, time
from pathlib import Path
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QApplication
app = QApplication([])
from insitu.sim.controller import SimController
from insitu.ui.model.session import RigChoice
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.open_files import open_file

do = SimController._do
SimController._do = lambda c, cmd: (time.sleep(0.002), do(c, cmd))[1]   # a slow board
w = MainWindow(QSettings(sys.argv[1], QSettings.Format.IniFormat))

def wait(ok, what):
    t0 = time.monotonic()
    while not ok():
        if time.monotonic() - t0 > 300:
            sys.exit(f"timed out waiting for {what}")
        app.processEvents()
        time.sleep(0.01)

w.connect_rig(RigChoice(binning=4))
wait(lambda: w.station is not None, "the rig")
open_file(w, Path(sys.argv[2]))
wait(lambda: w.session.cloud is not None, "the cloud")
w.place_panel.add_pattern(sys.argv[3])
w.session.update_selected(at_mm=(0.0, 28.0), width_mm=12.0, hatch_mm=float(sys.argv[4]))
wait(lambda: w.mark_panel.job() is not None and not w._plan_timer.isActive()
     and not w.runner.running("plan"), "the plan")
w.mark_panel.mark()
w.mark_panel.arm_dialog.accept()
print("marking", w.mark_panel.job_path(), flush=True)
app.exec()
"""


def mark_log(log: Path) -> Counter:
    """Every mark move the simulated board executed, from its mark log (all runs)."""
    moves = Counter()
    for line in log.read_text().splitlines():
        w = line.split()
        if len(w) == 8 and w[0] == "M":
            v = tuple(round(float(x), 6) for x in w[2:])
            moves[(v[:3], v[3:])] += 1
    return moves


def test_no_path_marked_twice_after_the_application_is_killed_unsaved(qtbot, tmp_path,
                                                                       monkeypatch):
    """The application (its own process) marks a project never saved and is killed
    (SIGKILL) mid-job; started again, it opens that job, Resume continues the cut path where
    the board stopped, and the board's own log shows every mark once."""
    from insitu import services
    from insitu.formats.pointcloud import write_ply

    write_ply(tmp_path / "cloud.ply", services.scan_replay(DATA / "scan-step-block-b4").cloud)
    settings, log = tmp_path / "settings.ini", tmp_path / "marks.log"
    env = {**os.environ, MARK_LOG_ENV: str(log), "QT_QPA_PLATFORM": "offscreen",
           "PYTHONPATH": str(SRC)}
    app = subprocess.Popen([sys.executable, "-c", APP, str(settings), str(tmp_path / "cloud.ply"),
                            PATTERN["spec"], str(HATCH_MM)], env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    work = tmp_path / "unsaved"
    t_end = time.monotonic() + 300
    journals = []
    while app.poll() is None and time.monotonic() < t_end and (
            not journals or journals[0].read_text().count('"done"') < 3):
        journals = list(work.glob("*.journal.jsonl")) if work.exists() else []
        time.sleep(0.01)
    app.send_signal(signal.SIGKILL)
    out, err = app.communicate(timeout=60)
    assert app.returncode == -signal.SIGKILL, out + err[-2000:]
    killed = read_journal(journals[0])
    assert killed.state == "killed" and 3 <= len(killed.done) < 53

    monkeypatch.setenv(MARK_LOG_ENV, str(log))          # the board outlives the application
    w = MainWindow(QSettings(str(settings), QSettings.Format.IniFormat))
    qtbot.addWidget(w)
    w.connect_rig(RigChoice(binning=4))
    w.restore_unfinished()                              # what insitu gui does at start
    panel = w.mark_panel
    qtbot.waitUntil(lambda: w.station is not None and w.session.job_file is not None,
                    timeout=WAIT_MS)
    job = read_job(w.session.job_file.path)
    assert w.session.job_file.path.parent == work
    assert "killed after" in panel.ui.resultLabel.text()          # and Resume finishes it
    qtbot.waitUntil(panel.resume_button.isEnabled, timeout=WAIT_MS)
    answer(["Continue the cut path", "Resume"])
    qtbot.mouseClick(panel.resume_button, Qt.LeftButton)
    fire(qtbot, w)

    def finished():
        assert panel.last_result is not None and not w.runner.running("mark"), \
            panel.ui.resultLabel.text()
    qtbot.waitUntil(finished, timeout=WAIT_MS)
    assert panel.last_result.state == "done"
    marked = mark_log(log)
    assert max(marked.values()) == 1                    # no mark twice, across the kill
    assert set(marked) == set(every_segment(w, job))    # and none left out
    w.runner.wait_all()
