"""The Production dock (pytest-qt, offscreen): File ▸ Save as recipe from the session, and a
short production run of two parts on the simulated rig driven from the dock: the log table,
the part's cloud with the located outline in the view, the read-back line, the log files."""

import json
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import QSettings, Qt

from insitu.errors import InsituError
from insitu.formats.mesh import write_mesh
from insitu.formats.pointcloud import PointCloud
from insitu.formats.production_log import PartRecord, read_log
from insitu.formats.recipe import Recipe, RecipeScan, write_recipe
from insitu.marking import Placement
from insitu.sim.workpieces import make_workpiece
from insitu.ui.model.session import RigChoice
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.production_panel import recipe_path, record_words, save_session_as_recipe

DATA = Path(__file__).parents[1] / "data"
SCAN = DATA / "scan-step-block-b4"
RUN_MS = 400_000


def _window(qtbot, tmp_path, binning):
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(w)
    w.resize(1200, 800)
    w.show()
    w.connect_rig(RigChoice(binning=binning))
    qtbot.waitUntil(lambda: w.station is not None, timeout=120_000)
    return w


def test_save_as_recipe_keeps_the_cloud_and_placements(qtbot, tmp_path):
    w = _window(qtbot, tmp_path, 4)
    try:
        ui = w.scan_panel.ui
        ui.sourceCombo.setCurrentIndex(1)
        ui.replayEdit.setText(str(SCAN))
        qtbot.mouseClick(ui.scanButton, Qt.LeftButton)
        qtbot.waitUntil(lambda: w.session.cloud is not None and not w.runner.running("scan"),
                        timeout=30_000)
        assert w.place_panel.add_pattern('qr:"{serial:05d}"')
        w.session.update_selected(at_mm=(0.0, 28.0), width_mm=8.0, rotate_deg=15.0)
        path = tmp_path / "r.json"
        save_session_as_recipe(w, path)
        raw = json.loads(path.read_text())
        assert raw["reference"] == {"cloud": "r.reference.ply"}
        assert raw["placements"][0]["at_mm"] == [0.0, 28.0]
        assert raw["placements"][0]["rotate_deg"] == 15.0
        assert raw["workpiece"] == "step-block" and raw["serial"]["start"] == 1
        assert w.production_panel.open_recipe(path)
        assert "1 placement(s)" in w.production_panel.recipeLabel.text()
        assert not w.production_panel.open_recipe(tmp_path / "missing.json")
        assert "missing.json" in w.production_panel.recipeLabel.text()
    finally:
        w.runner.wait_all()


def test_a_short_production_run_from_the_dock(qtbot, tmp_path):
    """Two parts at random poses, scanned with lines 1 mm apart and located against the part's
    mesh. Whether a part is found is the registration's to say (its own tests and benchmark):
    each row is marked — its serial next, read back — or refused without a serial."""
    w = _window(qtbot, tmp_path, 2)
    try:
        part = make_workpiece("step-block")
        write_mesh(tmp_path / "part.stl", np.array(part.vertices), np.array(part.triangles))
        write_recipe(tmp_path / "r.json", Recipe(
            tmp_path / "part.stl", "mesh", (Placement('qr:"{serial:03d}"', (0.0, -30.0), 7.35),),
            scan=RecipeScan(margin_mm=4.0, spacing_mm=1.0), serial_start=1,
            workpiece="step-block"))
        panel = w.production_panel
        assert panel.open_recipe(tmp_path / "r.json")
        panel.countSpin.setValue(2)
        panel.randomCheck.setChecked(True)
        panel.seedSpin.setValue(1)
        assert panel.startButton.isEnabled() and not panel.stopButton.isEnabled()
        qtbot.mouseClick(panel.startButton, Qt.LeftButton)
        qtbot.waitUntil(lambda: panel.stopButton.isEnabled(), timeout=5_000)
        qtbot.waitUntil(lambda: not w.runner.running("produce"), timeout=RUN_MS)
        assert panel.status.text().startswith("done: "), panel.status.text()
        log = tmp_path / "r.production.jsonl"
        records = read_log(log)
        assert panel.table.rowCount() == len(records) == 2
        assert log.with_suffix(".csv").read_text().count("\n") == 3
        marked = [r for r in records if r.outcome == "marked"]
        assert [r.serial for r in marked] == list(range(1, len(marked) + 1))
        assert all(r.outcome == "refused" and r.serial is None and r.error
                   for r in records if r.outcome != "marked")
        for row, r in enumerate(records):
            assert panel.table.item(row, 1).text() == r.outcome
            assert panel.table.item(row, 3).text() == ("" if r.serial is None else str(r.serial))
        assert w.view.renderer.points.count > 1000                    # the last part's cloud
        last = records[-1]
        assert panel.readbackLabel.text() == record_words(last)
        if last.x_mm is not None:                                     # located: its outline
            assert w.view.renderer.lines["located"][0].count > 0
        for r in marked:
            assert r.decoded == f"{r.serial:03d}" and r.decode_ok and r.grade
        if marked:
            assert not panel.readbackImage.pixmap().isNull()
        assert w.station.world.laser.kind == "off"
    finally:
        w.runner.wait_all()


def test_a_refused_part_says_why_in_its_row_production_reason(qtbot, tmp_path):
    """Save as recipe checks the reference (a part cut by the scan's edge: refused, nothing
    written) and names it .recipe.json; a refused part's row says why, in words and in its
    tooltip, with nothing of the session drawn over the part's cloud."""
    w = _window(qtbot, tmp_path, 4)
    try:
        ui = w.scan_panel.ui
        ui.sourceCombo.setCurrentIndex(1)
        ui.replayEdit.setText(str(SCAN))
        qtbot.mouseClick(ui.scanButton, Qt.LeftButton)
        qtbot.waitUntil(lambda: w.session.cloud is not None and not w.runner.running("scan"),
                        timeout=30_000)
        full = w.session.cloud
        assert w.place_panel.add_pattern('qr:"{serial:05d}"')
        keep = full.points[:, 0] < np.percentile(full.points[:, 0], 60)
        w.session.set_cloud(PointCloud(full.points[keep],
                                       {k: v[keep] for k, v in full.attributes.items()}))
        cut = recipe_path(tmp_path / "cut")
        with pytest.raises(InsituError, match="reaches the scan's edge"):
            save_session_as_recipe(w, cut)
        assert cut.name == "cut.recipe.json" and not cut.exists()
        assert not list(tmp_path.glob("cut*"))
        w.undo_action.trigger()
        assert w.session.cloud is full
        path = recipe_path(tmp_path / "r")
        check = save_session_as_recipe(w, path)
        assert path.name == "r.recipe.json" and path.exists()
        assert (tmp_path / "r.reference.ply").exists() and check.level != "refused"
        assert f"{check.coverage:.0%} of the part's top" in check.text

        panel = w.production_panel
        assert panel.open_recipe(path)
        assert panel.log_path().name == "r.production.jsonl"
        lines = w.view.renderer.lines

        def session_drawn() -> int:
            return sum(buf.count for name, (buf, *_r) in lines.items()
                       if name in ("placed", "selected", "warnings", "pilot", "located")
                       or name.startswith("projected"))
        w.view.set_lines("located", np.ones((2, 3), np.float32), (1, 1, 1, 1))  # a part before
        qtbot.waitUntil(lambda: session_drawn() > 2, timeout=30_000)
        reason = ("part not found: at best the reference fits 41 % of the scan (at least "
                  "80 % needed): is the part on the table and in the scan region?")
        panel._bridge.record.emit(PartRecord(part=1, serial=1, outcome="marked", x_mm=1.0,
                                             y_mm=2.0, angle_deg=3.0, time="t"))
        panel._bridge.record.emit(PartRecord(part=2, outcome="refused", error=reason,
                                             time="t"))
        qtbot.waitUntil(lambda: panel.table.rowCount() == 2, timeout=5_000)
        header = [panel.table.horizontalHeaderItem(c).text() for c in range(3)]
        assert header == ["part", "outcome", "reason"]
        cells = [panel.table.item(1, c).text() for c in range(4)]
        assert cells == ["2", "refused", reason, ""]
        assert all(reason in panel.table.item(1, c).toolTip()
                   for c in range(panel.table.columnCount()))
        assert panel.readbackLabel.text() == f"part 2: refused — {reason}"
        assert "None" not in panel.readbackLabel.text()
        assert session_drawn() == 0 and w.view.handles is None
    finally:
        w.runner.wait_all()
