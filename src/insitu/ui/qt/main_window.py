"""The main window of ``insitu gui``: the 3-D view in the middle, docks for Scan, Place, Mark,
Engrave, Calibrate, Production and the camera; menus, toolbar, status bar (messages, camera, scan
head, calibration age, where the journal is kept); the rig (:mod:`.rig_connection`) and
the project files (:mod:`.project_files`); undo/redo, the keys of a laser station
(:mod:`.keys`), drag-and-drop of patterns, projects, clouds, jobs."""

from __future__ import annotations

from PySide6.QtCore import QSettings, Qt, QTimer
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QDockWidget, QLabel, QMainWindow

from insitu.patterns import FILE_SUFFIXES
from insitu.services.mark_job import preview_plans
from insitu.services.plan import PlanOutcome
from insitu.services.station import Station
from insitu.ui.model.dirty import SavedState
from insitu.ui.model.session import Session
from insitu.ui.qt import keys, open_files
from insitu.ui.qt.calibrate_panel import CalibratePanel
from insitu.ui.qt.camera_window import CameraDock
from insitu.ui.qt.dialogs import ask_abort
from insitu.ui.qt.engrave_panel import EngravePanel
from insitu.ui.qt.fit_label import FitLabel
from insitu.ui.qt.forms import icon
from insitu.ui.qt.help import add_help_menu
from insitu.ui.qt.mark_panel import MarkPanel
from insitu.ui.qt.place_panel import PlacePanel
from insitu.ui.qt.production_panel import ProductionPanel, save_recipe_dialog
from insitu.ui.qt.project_files import ProjectFiles
from insitu.ui.qt.rig_connection import RigConnection
from insitu.ui.qt.scan_panel import ScanPanel
from insitu.ui.qt.scene_binding import SceneBinding
from insitu.ui.qt.view3d import View3D
from insitu.ui.qt.view_menu import ViewMenu
from insitu.ui.qt.workers import TaskRunner

PLAN_DELAY_MS = 150
ERROR_STYLE = "color: #ff6b5e;"


class MainWindow(ProjectFiles, RigConnection, QMainWindow):
    def __init__(self, settings: QSettings | None = None):
        super().__init__()
        self.setWindowIcon(icon("app"))
        self.setAcceptDrops(True)
        self.resize(1280, 800)
        self.settings = settings or QSettings("insitu", "insitu gui")
        self.session = Session()
        self.runner = TaskRunner(self)
        self.station: Station | None = None
        self.connecting = False
        self._rig_epoch = 0             # a connection started before a disconnect is dropped
        self._plan_timer = QTimer(self, singleShot=True, interval=PLAN_DELAY_MS)
        self.view = View3D(self)
        self.setCentralWidget(self.view)
        self.binding = SceneBinding(self.session, self.view)
        self.camera_dock = CameraDock(self)
        self.camera_image = self.camera_dock.image
        self.scan_panel = ScanPanel(self)
        self.place_panel = PlacePanel(self)
        self.mark_panel = MarkPanel(self)
        self.engrave_panel = EngravePanel(self)
        self.calibrate_panel = CalibratePanel(self)
        self.production_panel = ProductionPanel(self)
        self._docks()
        self._status_bar()
        self._actions()
        self.saved = SavedState(self._kept_state)
        self._plan_timer.timeout.connect(self.plan)
        self._plan_again = False
        s = self.session
        for sig in (s.placements.changed, s.cloud_changed, s.pens_changed):
            sig.connect(lambda: self._plan_timer.start())
            sig.connect(self.update_title)
        s.placements.changed.connect(self.show_journal_place)
        s.job_file_changed.connect(lambda: open_files.show_job_file(self))
        s.job_file_changed.connect(self.show_journal_place)
        self.scan_panel.settings_changed.connect(self.update_title)
        self.view.pattern_moved.connect(self._moved)
        self.view.rotate_dragged.connect(self._rotated)
        self.view.scale_dragged.connect(self._scaled)
        self.view.region_drawn.connect(self._region_drawn)
        self.view.box_selected.connect(self._box_selected)
        self.view.clicked_at.connect(self._clicked_at)
        self.view.gl_ready.connect(lambda name: self.gl_label.setText(f"GL: {name}"))
        self._scale_start: tuple[object, float] | None = None
        self.update_title()
        self.show_journal_place()
        self.view.setFocus()

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
                      "engrave": dock("Engrave", self.engrave_panel, right),
                      "calibrate": dock("Calibrate", self.calibrate_panel, right),
                      "production": dock("Production", self.production_panel, right),
                      "camera": dock("Camera", self.camera_dock, Qt.LeftDockWidgetArea)}
        for name in ("place", "mark", "engrave", "calibrate", "production"):
            self.tabifyDockWidget(self.docks["scan"], self.docks[name])
        self.docks["scan"].raise_()

    def _status_bar(self) -> None:
        bar = self.statusBar()
        self.message_label = FitLabel()
        self.message_label.setObjectName("messageLabel")
        self.journal_label = FitLabel(elide=Qt.TextElideMode.ElideMiddle)
        self.journal_label.setObjectName("journalLabel")
        self.journal_label.setMaximumWidth(320)
        self.camera_label = QLabel("camera: not connected")
        self.head_label = QLabel("scan head: not connected")
        self.calib_label = QLabel("no height calibration")
        self.gl_label = QLabel("GL: —")
        self._message_source: str | None = None
        bar.addWidget(self.message_label, 1)
        bar.addPermanentWidget(self.journal_label, 1)
        for w in (self.camera_label, self.head_label, self.calib_label, self.gl_label):
            bar.addPermanentWidget(w)

    def _action(self, menu, text, slot, shortcut=None, icon_name=None) -> QAction:
        a = QAction(text, self)
        if shortcut:
            a.setShortcuts(shortcut if isinstance(shortcut, list) else [QKeySequence(shortcut)])
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
        self.view_menu = ViewMenu(mb.addMenu("&View"), self)
        keys.add_laser_menu(self, mb.addMenu("&Laser"), tb)
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
        """One line in the status bar, replacing the last (an error too: it no longer
        holds); the whole text in its tooltip where it is cut. ``source`` names the state it
        tells of, so :meth:`clear_message` takes it away once that no longer holds."""
        self.message_label.setStyleSheet("")
        self.message_label.set_text(text)
        self._message_source = source

    def show_error(self, text: str, source: str | None = None) -> None:
        """One line in the status bar, in red (no dialog: the station keeps running); the
        whole text in its tooltip."""
        self.message_label.setStyleSheet(ERROR_STYLE)
        self.message_label.set_text(text.splitlines()[0] if text else "error", text)
        self._message_source = source

    def clear_message(self, source: str) -> None:
        """Take away the message of ``source`` (and only it): what it said no longer holds."""
        if self._message_source == source:
            self.show_message("")

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

    def _nudged(self, dx: float, dy: float) -> None:
        """An arrow key in the view: the selected pattern moved by (dx, dy) mm."""
        p = self.session.current()
        if p is not None:
            self.session.update_selected(at_mm=(round(p.at_mm[0] + dx, 3),
                                                round(p.at_mm[1] + dy, 3)))

    def _box_selected(self, box) -> None:
        from insitu.ui.model.scene_data import pattern_in_box
        self.session.select(pattern_in_box(self.session.placements.items, box))

    def _clicked_at(self, x: float, y: float) -> None:
        from insitu.ui.model.scene_data import pattern_at
        i = pattern_at(self.session.placements.items, (x, y))
        if i >= 0:
            self.session.select(i)

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
            why = ("no point cloud: scan or open one" if cloud is None else
                   "the rig is connecting…" if self.connecting else "connect the rig")
            s.set_plans([PlanOutcome.refused("station", why) for _ in items])
            return
        if self.runner.running("plan"):
            self._plan_again = True
            return
        station, path, pens, source = self.station, self.job_path(), s.pens, s.cloud_path
        self.runner.start("plan", lambda p, c, f: (items, pens, preview_plans(
            station, cloud, items, pens, path, source)),
                          self._planned, lambda m, _c: self.show_error(m, "plan"))

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

    # -- drag and drop -------------------------------------------------------------------
    def dragEnterEvent(self, e) -> None:
        if e.mimeData().hasUrls():
            e.acceptProposedAction()

    def dropEvent(self, e) -> None:
        from pathlib import Path

        for url in e.mimeData().urls():
            path = Path(url.toLocalFile())
            if open_files.kind_of(path) is not None:
                self.open_file(path)
            elif path.suffix.lower() in FILE_SUFFIXES:
                self.place_panel.add_pattern(str(path))
                self.docks["place"].raise_()
            else:
                self.show_error(f"{path.name}: not a pattern (SVG, DXF, image), a project, a "
                                "point cloud (.ply) or a mark job (.json)", "drop")

    def closeEvent(self, e) -> None:
        """Quit only when no marking runs (or the operator aborts it) and nothing unsaved is
        lost (Save / Discard / Cancel)."""
        if self.runner.running("mark") or self.runner.running("engrave"):
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
