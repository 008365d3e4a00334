"""Opening a project never connects its rig: the window shows the project and says the rig is
not connected; a native library the rig file names is loaded only when the operator connects
and the station file allows it (a canary library whose constructor creates a file)."""

from pathlib import Path

from PySide6.QtCore import QSettings

from fakes.canary import build, project_naming
from fakes.station import allow
from insitu.formats.project import RigChoice
from insitu.ui.qt.main_window import MainWindow

WAIT_MS = 60_000


def connect(qtbot, w: MainWindow) -> str:
    w.connect_action.trigger()
    qtbot.waitUntil(lambda: not w.runner.running("connect"), timeout=WAIT_MS)
    return w.message_label.full_text()


def test_opening_a_project_runs_none_of_its_rigs_code(qtbot, tmp_path: Path):
    lib, marker = build(tmp_path)
    project, rig = project_naming(tmp_path, lib)
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(w)
    w.open_project(project)
    qtbot.waitUntil(lambda: w.session.project_path == project, timeout=WAIT_MS)
    assert w.session.rig_choice.rig_file == rig and not w.runner.running("connect")
    assert w.station is None and w.head_label.text() == "scan head: not connected"
    assert w.connect_action.text() == "&Connect rig rig.json"
    assert "rig not connected" in w.message_label.full_text()
    assert not marker.exists()
    msg = connect(qtbot, w)                     # the operator connects: the station refuses
    assert "native library" in msg and lib.name in msg and "not allowed" in msg
    assert w.station is None and not marker.exists()
    allow(lib)                                  # with the station's consent it is loaded
    assert "not an RTC6 library" in connect(qtbot, w)
    assert marker.exists() and w.station is None
    w.runner.wait_all()


def test_a_connection_under_way_when_a_project_opens_is_dropped(qtbot, tmp_path: Path):
    lib, marker = build(tmp_path)
    project, _ = project_naming(tmp_path, lib)
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(w)
    w.connect_rig(RigChoice(binning=4))         # the simulated rig, still connecting …
    w.open_project(project)                     # … when the project opens
    qtbot.waitUntil(lambda: w.session.project_path == project
                    and not w.runner.running("connect"), timeout=WAIT_MS)
    assert w.station is None and w.head_label.text() == "scan head: not connected"
    assert w.connect_action.text() == "&Connect rig rig.json" and not marker.exists()
    w.runner.wait_all()
