"""One verdict: the application's Place dock and ``insitu mark`` say the same of the same
placement on the same cloud — refused or not, and every finding (what a step leaves unmarked,
a code that would not read, the scan field, the focus range, the loader's warnings)."""

import re
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import QSettings
from typer.testing import CliRunner

from insitu import services
from insitu.cli.main import app
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.ui.model.session import RigChoice
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.open_files import open_file

DATA = Path(__file__).parents[1] / "data"
WAIT_MS = 60_000


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    """The recorded step block (Method 1), a flat plate 40 mm above the focal plane and one
    reaching past the scan field's edge (x = 100 mm)."""
    d = tmp_path_factory.mktemp("verdict")
    write_ply(d / "step-block.ply", services.scan_replay(DATA / "scan-step-block-b4").cloud)
    xs, ys = np.meshgrid(np.linspace(-15, 15, 121), np.linspace(-15, 15, 121))
    write_ply(d / "high.ply", PointCloud(np.c_[xs.ravel(), ys.ravel(), np.full(xs.size, 40.0)]))
    write_ply(d / "edge.ply", PointCloud(np.c_[xs.ravel() / 2 + 100, ys.ravel(), np.zeros(xs.size)]))
    return d


CASES = {   # (cloud, pattern, at, width, what both must say)
    "across_step": ("step-block.ply", 'qr:"SN 0042"', (0.0, 0.0), 8.0,
                    ["unmarked at walls", "does not decode", "left unmarked at a step's wall"]),
    "unreadable_code": ("step-block.ply", "qr:HELLO;module=0.25;hatch=0.6", (0.0, -30.0),
                        5.25, ["does not decode"]),
    "field": ("edge.ply", 'text:"A"', (99.0, 0.0), 8.0, ["outside the scan field"]),
    "focus": ("high.ply", 'text:"A"', (0.0, 0.0), 8.0, ["focus"]),
    "fine": ("step-block.ply", 'qr:"SN 0042"', (0.0, -30.0), 8.0, ["decodes yes"]),
}


def _flat(text: str) -> str:
    return " ".join(re.sub(r"[│┃┌┐└┘├┤┬┴┼─]", " ", text).split())


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_place_dock_and_insitu_mark_give_the_same_verdict_across_step(qtbot, tmp_path,
                                                                          clouds, case):
    name, spec, at, width, says = CASES[case]
    hatch = None
    if ";hatch=" in spec:
        spec, hatch = spec.split(";hatch=")[0], float(spec.split(";hatch=")[1])
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    w.connect_rig(RigChoice(binning=4))
    qtbot.waitUntil(lambda: w.station is not None, timeout=WAIT_MS)
    open_file(w, clouds / name)
    qtbot.waitUntil(lambda: w.session.cloud is not None, timeout=WAIT_MS)
    assert w.place_panel.add_pattern(spec)
    w.session.update_selected(at_mm=at, **({"width_mm": width} if width else {}),
                              **({"hatch_mm": hatch} if hatch else {}))
    qtbot.waitUntil(lambda: len(w.session.plans) == 1 and not w.runner.running("plan")
                    and not w._plan_timer.isActive(), timeout=WAIT_MS)
    outcome = w.session.plans[0]
    shown = w.place_panel.ui.statusLabel.text()

    args = ["mark", "--cloud", str(clouds / name), "--pattern", spec, "--at", *map(str, at),
            "-o", str(tmp_path / "job.json")]
    args += ["--width", str(width)] if width else []
    args += ["--hatch", str(hatch)] if hatch else []
    res = CliRunner().invoke(app, args)
    said = _flat(res.output)

    assert (res.exit_code == 0) == (outcome.plan is not None), (res.output, shown)
    assert (tmp_path / "job.json").exists() == (outcome.plan is not None)
    refused = [f for f in outcome.findings if f.level == "refused"]
    for f in outcome.findings:      # a refused job: the command says its warnings and why
        if f.check == "rig" or (refused and f.level == "info") or (f.level == "refused"
                                                                   and f is not refused[0]):
            continue                # the rig's line names the station (binned otherwise)
        assert f.line() in shown and _flat(f.text) in said, (f, shown, said)
    for words in says:
        assert words in shown and words in said, (words, shown, said)
    w.saved.mark_clean()
    w.close()
