"""The main window of ``insitu gui``: the 3-D view in the middle, docks for Scan, Place, Mark,
Calibrate and the camera; menus, toolbar, status bar (camera, scan head, calibration age),
project files with recent files (and clouds and jobs: :mod:`insitu.ui.qt.open_files`),
unsaved changes asked about, undo/redo, drag-and-drop of patterns, projects, clouds, jobs."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSettings, Qt, QTimer
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QDockWidget, QFileDialog, QLabel, QMainWindow

from insitu.errors import InsituError
from insitu.formats.project import SUFFIX, Project, RigChoice, beside
from insitu.patterns import FILE_SUFFIXES
from insitu.services import load_height_calibration
from insitu.services.mark_job import preview_plans
from insitu.services.plan import PlanOutcome
from insitu.services.project import OpenedProject, open_project, save_project
from insitu.services.serials import is_templated
from insitu.services.station import Station
from insitu.ui.model import operations as ops
from insitu.ui.model.dirty import SavedState
from insitu.ui.model.session import Session
from insitu.ui.qt.calibrate_panel import CalibratePanel
from insitu.ui.qt.camera_window import CameraDock
from insitu.ui.qt.dialogs import ask_abort, ask_save
from insitu.ui.qt.forms import icon
from insitu.ui.qt.help import add_help_menu
from insitu.ui.qt.keys import route_undo
from insitu.ui.qt.mark_panel import MarkPanel
from insitu.ui.qt import open_files
from insitu.ui.qt.place_panel import PlacePanel
from insitu.ui.qt.production_panel import ProductionPanel, save_recipe_dialog
from insitu.ui.qt.scan_panel import ScanPanel
from insitu.ui.qt.scene_binding import SceneBinding
from insitu.ui.qt.view3d import View3D
from insitu.ui.qt.view_menu import ViewMenu
from insitu.ui.qt.workers import TaskRunner

MAX_RECENT = 8
PLAN_DELAY_MS = 150


def age_text(created: str | None) -> str:
    """"2 h old" from an ISO-8601 UTC time."""
    try:
        t = datetime.fromisoformat(created.replace("Z", "+00:00"))
    except (AttributeError, ValueError):
        return "age unknown"
    s = (datetime.now(timezone.utc) - t).total_seconds()
    for unit, n in (("d", 86400), ("h", 3600), ("min", 60)):
        if s >= n:
            return f"{s / n:.0f} {unit} old"
    return "new"


class MainWindow(QMainWindow):
    def __init__(self, settings: QSettings | None = None):
        super().__init__()
        self.setWindowTitle("insitu")
        self.setWindowIcon(icon("app"))
        self.setAcceptDrops(True)
        self.resize(1280, 800)
        self.settings = settings or QSettings("insitu", "insitu gui")
        self.session = Session()
        self.runner = TaskRunner(self)
        self.station: Station | None = None
        self._rig_epoch = 0             # a connection started before a disconnect is dropped
        self.view = View3D(self)
        self.setCentralWidget(self.view)
        self.binding = SceneBinding(self.session, self.view)
        self.camera_dock = CameraDock(self)
        self.camera_image = self.camera_dock.image
        self.scan_panel = ScanPanel(self)
        self.place_panel = PlacePanel(self)
        self.mark_panel = MarkPanel(self)
        self.calibrate_panel = CalibratePanel(self)
        self.production_panel = ProductionPanel(self)
        self._docks()
        self._status_bar()
        self._actions()
        self.saved = SavedState(self._kept_state)
        route_undo(self.place_panel, self.undo_action, self.redo_action)
        self._plan_timer = QTimer(self, singleShot=True, interval=PLAN_DELAY_MS)
        self._plan_timer.timeout.connect(self.plan)
        self._plan_again = False
        for sig in (self.session.placements.changed, self.session.cloud_changed,
                    self.session.pens_changed):
            sig.connect(lambda: self._plan_timer.start())
        self.session.job_file_changed.connect(lambda: open_files.show_job_file(self))
        self.view.pattern_moved.connect(self._moved)
        self.view.rotate_dragged.connect(self._rotated)
        self.view.scale_dragged.connect(self._scaled)
        self.view.region_drawn.connect(self._region_drawn)
        self.view.gl_ready.connect(lambda name: self.gl_label.setText(f"GL: {name}"))
        self._scale_start: tuple[object, float] | None = None

    # -- layout --------------------------------------------------------------------------
    def _docks(self) -> None:
        def dock(title, widget, area):
            d = QDockWidget(title, self)
            d.setObjectName(f"{title.lower()}Dock")
            d.setWindowIcon(icon(title.lower()))
            d.setWidget(widget)
            self.addDockWidget(area, d)
            return d
        right = Qt.RightDockWidgetArea
        self.docks = {"scan": dock("Scan", self.scan_panel, right),
                      "place": dock("Place", self.place_panel, right),
                      "mark": dock("Mark", self.mark_panel, right),
                      "calibrate": dock("Calibrate", self.calibrate_panel, right),
                      "production": dock("Production", self.production_panel, right),
                      "camera": dock("Camera", self.camera_dock, Qt.LeftDockWidgetArea)}
        for name in ("place", "mark", "calibrate", "production"):
            self.tabifyDockWidget(self.docks["scan"], self.docks[name])
        self.docks["scan"].raise_()

    def _status_bar(self) -> None:
        bar = self.statusBar()
        self.message_label = QLabel("")
        self.camera_label = QLabel("camera: not connected")
        self.head_label = QLabel("scan head: not connected")
        self.calib_label = QLabel("no height calibration")
        self.gl_label = QLabel("GL: —")
        self._message_source: str | None = None
        bar.addWidget(self.message_label, 1)
        for w in (self.camera_label, self.head_label, self.calib_label, self.gl_label):
            bar.addPermanentWidget(w)

    def _action(self, menu, text, slot, shortcut=None, icon_name=None) -> QAction:
        a = QAction(text, self)
        if shortcut:
            a.setShortcut(QKeySequence(shortcut))
        if icon_name:
            a.setIcon(icon(icon_name))
        a.triggered.connect(slot)
        menu.addAction(a)
        return a

    def _actions(self) -> None:
        mb, tb = self.menuBar(), self.addToolBar("Main")
        tb.setObjectName("mainToolBar")
        f = mb.addMenu("&File")
        self._action(f, "&New project", self.new_project, QKeySequence.New)
        tb.addAction(self._action(f, "&Open…", self._open_dialog, QKeySequence.Open, "open"))
        tb.addAction(self._action(f, "&Save project", self.save, QKeySequence.Save, "save"))
        self._action(f, "Save project &as…", self._save_dialog, QKeySequence.SaveAs)
        self._action(f, "Save as &recipe…", lambda: save_recipe_dialog(self))
        self.recent_menu = f.addMenu("Open &recent")
        self.export_action = self._action(f, "&Export job…", self._export_dialog)
        f.addSeparator()
        self.quit_action = self._action(f, "&Quit", self.close, "Ctrl+Q")  # every platform
        e = mb.addMenu("&Edit")
        self.undo_action = self._action(e, "&Undo", self.session.placements.undo,
                                        QKeySequence.Undo, "undo")
        self.redo_action = self._action(e, "&Redo", self.session.placements.redo,
                                        QKeySequence.Redo, "redo")
        self._action(e, "Remove pattern", self.session.remove_selected, QKeySequence.Delete)
        tb.addActions([self.undo_action, self.redo_action])
        self.session.placements.changed.connect(self._undo_state)
        self._undo_state()
        self.view_menu = ViewMenu(mb.addMenu("&View"), self.view, self.binding, self.session)
        r = mb.addMenu("&Rig")
        self.connect_action = self._action(r, "&Connect", lambda: self.connect_rig(), None,
                                           "connect")
        tb.addAction(self.connect_action)
        self._rig_named()
        self._action(r, "Connect with a rig &file…", self._rig_file_dialog)
        add_help_menu(self)
        self._update_recent()

    def _undo_state(self) -> None:
        self.undo_action.setEnabled(self.session.placements.can_undo())
        self.redo_action.setEnabled(self.session.placements.can_redo())

    # -- messages ------------------------------------------------------------------------
    def show_message(self, text: str, source: str | None = None) -> None:
        """One line in the status bar, replacing the last; ``source`` names the state it
        tells of, so :meth:`clear_message` takes it away once that no longer holds."""
        self.message_label.setStyleSheet("")
        self.message_label.setText(text)
        self._message_source = source

    def show_error(self, text: str, source: str | None = None) -> None:
        """One line in the status bar, in red (no dialog: the station keeps running)."""
        self.message_label.setStyleSheet("color: #ff6b5e;")
        self.message_label.setText(text.splitlines()[0] if text else "error")
        self._message_source = source

    def clear_message(self, source: str) -> None:
        """Take away the message of ``source`` (and only it): what it said no longer holds."""
        if self._message_source == source:
            self.show_message("")

    # -- rig -----------------------------------------------------------------------------
    def _rig_named(self) -> None:
        """Rig ▸ Connect names the rig it connects: the session's (a project's) choice."""
        rig_file = self.session.rig_choice.rig_file
        self.connect_action.setText("&Connect simulated rig" if rig_file is None
                                    else f"&Connect rig {Path(rig_file).name}")

    def disconnect_rig(self) -> None:
        """Close the station (laser off, devices released); the status says so."""
        self._rig_epoch += 1
        if self.station is not None:
            self.station.close()
            self.station = None
        self.camera_label.setText("camera: not connected")
        self.head_label.setText("scan head: not connected")
        self.clear_message("rig")
        self.session.rig_changed.emit()
        self._plan_timer.start()

    def connect_rig(self, choice: RigChoice | None = None) -> None:
        """Connect the station of ``choice`` (default: the session's), off the GUI thread.
        Only the operator's action (or ``insitu gui`` without a project) calls this: opening a
        project never connects its rig, so a rig file that came with it runs nothing."""
        choice = choice or self.session.rig_choice
        field, epoch = self.session.field_path, self._rig_epoch
        self.runner.start("connect", lambda p, c, f: (epoch, choice, ops.connect(choice, field)),
                          self._connected, lambda m, _c: self.show_error(m))

    def _connected(self, result) -> None:
        epoch, choice, station = result
        if epoch != self._rig_epoch:    # a project was opened meanwhile: not its rig
            station.close()
            return
        if self.station is not None:
            self.station.close()
        self.station = station
        self.session.rig_choice = choice
        self._rig_named()
        cam, head = station.describe()
        self.camera_label.setText(cam)
        self.head_label.setText(head)
        nominal = station.rig.head
        self.binding.show_field(nominal.field_size_mm, nominal.z_range_mm)
        if self.session.cloud is None:            # the whole scan field
            hx, hy = np.asarray(nominal.field_size_mm, float) / 2
            self.view.frame_all((-hx, -hy, min(nominal.z_range_mm)),
                                (hx, hy, max(nominal.z_range_mm)))
        self.session.rig_changed.emit()
        self._plan_timer.start()
        self.show_message("rig connected", "rig")

    def _rig_file_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Rig file", "", "Rig files (*.json)")
        if path:
            from dataclasses import replace
            self.connect_rig(replace(self.session.rig_choice, rig_file=Path(path)))

    def load_height_cal(self, path: Path | None) -> None:
        """Use the height calibration file (or recorded folder, fitted now) ``path``."""
        if path is None:
            self.session.height_cal_path = self.session.height_cal = None
            self.calib_label.setText("no height calibration")
            return
        self.runner.start("height-cal", lambda p, c, f: (path, load_height_calibration(path, p)),
                          self._height_cal_loaded, lambda m, _c: self.show_error(m))

    def _height_cal_loaded(self, result) -> None:
        path, cal = result
        self.session.height_cal_path, self.session.height_cal = path, cal
        self.scan_panel.ui.heightCalEdit.setText(str(path))
        self.calib_label.setText(f"height calibration {age_text(cal.created)}")

    def calibration_done(self, kind: str, path: Path) -> None:
        if kind == "height":
            self.load_height_cal(path)
        elif kind == "field":
            self.session.field_path = path
            if self.station is not None:
                self.station.use_field(path)
                self._plan_timer.start()
        else:
            self.session.camera_cal_path = path

    # -- placement from the 3-D view -----------------------------------------------------
    def _moved(self, x: float, y: float, key) -> None:
        self.session.update_selected(key, at_mm=(round(x, 3), round(y, 3)))

    def _rotated(self, x: float, y: float, key) -> None:
        from insitu.ui.model.scene_data import rotate_to
        p = self.session.current()
        if p is not None:
            self.session.update_selected(key, rotate_deg=rotate_to(p, (x, y)))

    def _scaled(self, x0: float, y0: float, x: float, y: float, key) -> None:
        from insitu.ui.model.scene_data import scale_to
        p = self.session.current()
        if p is None:
            return
        if self._scale_start is None or self._scale_start[0] is not key:
            self._scale_start = (key, p.width_mm)
        self.session.update_selected(key, width_mm=scale_to(p, self._scale_start[1], (x0, y0),
                                                            (x, y)))

    def _region_drawn(self, region) -> None:
        self.scan_panel.set_region(region)
        self.binding.show_region(region)

    # -- planning ------------------------------------------------------------------------
    def plan(self) -> None:
        """Project and check every placement on a worker (again when it ends, if changed)."""
        s = self.session
        items, cloud = s.placements.items, s.cloud
        if not items:
            s.set_plans([])
            return
        if cloud is None or self.station is None:
            why = "no point cloud: scan or open one" if cloud is None else "connect the rig"
            s.set_plans([PlanOutcome.refused("station", why) for _ in items])
            return
        if self.runner.running("plan"):
            self._plan_again = True
            return
        station, path, pens, source = self.station, self.job_path(), s.pens, s.cloud_path
        self.runner.start("plan", lambda p, c, f: (items, pens, preview_plans(
            station, cloud, items, pens, path, source)),
                          self._planned, lambda m, _c: self.show_error(m))

    def _planned(self, result) -> None:
        items, pens, plans = result
        current = (self.session.placements.items, self.session.pens)
        if (items, pens) == current and not self._plan_again:
            self.session.set_plans(plans)
            refused = [(i, p.error) for i, p in enumerate(plans) if p.error]
            if refused:
                i, why = refused[0]
                self.show_error(f"placement {i + 1} refused: {why}", "plan")
            else:
                self.clear_message("plan")
        else:
            self._plan_again = False
            self._plan_timer.start()

    # -- projects ------------------------------------------------------------------------
    def job_path(self) -> Path | None:
        p = self.session.project_path
        return None if p is None else beside(p, ".job.json")

    def _kept_state(self) -> dict:
        """What a project file keeps of the session (see :class:`SavedState`)."""
        s = self.session
        return {"placements": s.placements.items, "cloud": s.cloud,
                "height calibration": s.height_cal_path, "field correction": s.field_path,
                "camera calibration": s.camera_cal_path,
                "scan settings": self.scan_panel.settings()}

    def may_discard(self, what: str) -> bool:
        """True when the session may be replaced (``what``: "quitting", …): nothing unsaved,
        or the operator saved it or chose to discard it."""
        if not self.saved.dirty():
            return True
        answer = ask_save(self, self.saved.changes(), what)
        return answer == "discard" or (answer == "save" and self.save())

    def new_project(self) -> None:
        if not self.may_discard("starting a new project"):
            return
        self.session.set_job_file(None)
        self.session.set_cloud(None)
        self.session.placements.reset()
        self.session.project_path = None
        self.setWindowTitle("insitu")
        self.saved.mark_clean()

    def _open_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open", "", open_files.OPEN_FILTERS)
        if path:
            self.open_file(Path(path))

    def open_file(self, path: Path) -> None:
        """Open a project, a point cloud or a mark job (by its name), after asking to save
        unsaved changes where it replaces them."""
        open_files.open_file(self, path)

    def _export_dialog(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Export job", "", open_files.JOB_FILES)
        if path:
            open_files.export_job(self, Path(path if path.endswith(".json") else
                                             path + ".json"))

    def _save_dialog(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Save project", "", open_files.PROJECT_FILES)
        if path:
            self.save(Path(path if path.endswith(SUFFIX) else path + SUFFIX))

    def open_project(self, path: Path) -> None:
        self.runner.start("open", lambda p, c, f: open_project(path, p),
                          lambda opened: self._opened(path, opened),
                          lambda m, _c: self.show_error(m))

    def _opened(self, path: Path, opened: OpenedProject) -> None:
        pr, s = opened.project, self.session
        s.project_path = path
        s.height_cal_path, s.height_cal = pr.height_cal, opened.height_cal
        s.field_path, s.camera_cal_path = pr.field_correction, pr.camera_cal
        self.disconnect_rig()           # its rig and field correction: when the operator connects
        s.rig_choice = pr.rig
        self._rig_named()
        self.scan_panel.show_settings(pr.scan)
        self.scan_panel.ui.heightCalEdit.setText(str(pr.height_cal or ""))
        if opened.height_cal is not None:
            self.calib_label.setText(f"height calibration {age_text(opened.height_cal.created)}")
        self.binding.show_region(pr.scan.region)
        s.set_job_file(None)
        s.set_cloud(opened.cloud, pr.cloud)
        s.set_pens(pr.pens)
        s.placements.reset(pr.placements)
        s.select(pr.selected)
        self.saved.mark_clean()
        self._remember(path)
        self.setWindowTitle(f"insitu — {path.name}")
        self.show_message(f"opened {path}; rig not connected: "
                          f"{self.connect_action.text().replace('&', '')} (Rig menu)")

    def save(self, path: Path | None = None) -> bool:
        """Save the session to ``path`` (default: where it came from); True when written."""
        path = path or self.session.project_path
        if path is None:
            self._save_dialog()
            return self.session.project_path is not None
        s = self.session
        project = Project(s.rig_choice, s.height_cal_path, s.field_path, s.camera_cal_path,
                          self.scan_panel.settings(), s.cloud_path, s.placements.items,
                          s.selected, None, s.pens)
        # a job with variable data is written when it is marked, with the serial it takes
        job = None if is_templated(s.placements.items) else self.mark_panel.job()
        try:
            written = save_project(path, project, s.cloud, job)
        except InsituError as e:
            self.show_error(str(e))
            return False
        s.project_path, s.cloud_path = path, written.cloud
        self.saved.mark_clean()
        self._remember(path)
        self.setWindowTitle(f"insitu — {path.name}")
        self.show_message(f"saved {path}")
        return True

    def _remember(self, path: Path) -> None:
        recent = [str(path)] + [p for p in self.recent_files() if p != str(path)]
        self.settings.setValue("recent_projects", recent[:MAX_RECENT])
        self._update_recent()

    def recent_files(self) -> list[str]:
        v = self.settings.value("recent_projects", [])
        return [v] if isinstance(v, str) else list(v or [])

    def _update_recent(self) -> None:
        self.recent_menu.clear()
        for p in self.recent_files():
            self.recent_menu.addAction(p, lambda p=p: self.open_file(Path(p)))
        self.recent_menu.setEnabled(bool(self.recent_files()))

    # -- drag and drop -------------------------------------------------------------------
    def dragEnterEvent(self, e) -> None:
        if e.mimeData().hasUrls():
            e.acceptProposedAction()

    def dropEvent(self, e) -> None:
        for url in e.mimeData().urls():
            path = Path(url.toLocalFile())
            if open_files.kind_of(path) is not None:
                self.open_file(path)
            elif path.suffix.lower() in FILE_SUFFIXES:
                self.place_panel.add_pattern(str(path))
                self.docks["place"].raise_()
            else:
                self.show_error(f"{path.name}: not a pattern (SVG, DXF, image), a project, a "
                                "point cloud (.ply) or a mark job (.json)")

    def closeEvent(self, e) -> None:
        """Quit only when no marking runs (or the operator aborts it) and nothing unsaved is
        lost (Save / Discard / Cancel)."""
        if self.runner.running("mark"):
            if not ask_abort(self):
                e.ignore()
                return
            self.mark_panel.abort()
        if not self.may_discard("quitting"):
            e.ignore()
            return
        self.runner.wait_all()
        if self.station is not None:
            self.station.close()            # laser off, devices released
        super().closeEvent(e)
