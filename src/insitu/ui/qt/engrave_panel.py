"""The Engrave dock: the selected pattern's pocket — its depth map from the scanned cloud
against the top around it (Depth map) or from a scan of its own on the rig, as an engraving measures
between rounds (Measure pocket, :mod:`insitu.services.pocket`), and Engrave… to a target depth in a
material, armed as Mark is (what will be engraved, confirmed in the same dialog; the laser never
fires without it), run on the station off the GUI thread (:func:`insitu.services.engrave.engrave`:
rounds of passes, each followed by a scan of the pocket), each re-measure's depth map shown as it
comes, ABORT (the Laser menu's, Esc, Space) stopping it with the laser off, and how it ended in
words. The map: a picture with a colour bar in mm, the hidden cells hatched, the ones not measured
grey, their counts and the mean depth and 95 % band in words."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path

from PySide6.QtCore import QObject, Qt, Signal
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from insitu.errors import InsituError
from insitu.formats.materials import DEFAULT_MATERIALS
from insitu.marking.engrave_record import read_record
from insitu.ui.model.depth_view import DepthSummary, depth_picture, measure_pocket, pocket_region
from insitu.ui.model.engrave_words import engrave_rows, measure_line, verdict
from insitu.ui.qt.dialogs import ArmDialog
from insitu.ui.qt.forms import icon
from insitu.ui.qt.image_view import ImageView
from insitu.ui.qt.place_panel import short_name


class _Bridge(QObject):
    """Hands the worker's re-measures and notes to the GUI thread (queued signals)."""

    measured = Signal(object, object)
    note = Signal(str)


@dataclass(frozen=True)
class _Armed:
    """What the operator is asked to confirm: the request and what it was made of."""

    request: object                 # insitu.services.engrave.EngraveRequest
    station: object                 # the station it was armed on
    region: object

    def holds(self, sel, cloud, station) -> bool:
        """Whether the selection ``sel`` (placement, plan), ``cloud`` and ``station`` are
        still the ones armed (a resume: the station alone, its request is the record's)."""
        if self.request.resume:
            return station is self.station
        return (sel is not None and sel[0] == self.request.placement
                and cloud is self.request.cloud and station is self.station)


class EngravePanel(QWidget):
    def __init__(self, window, parent=None):
        super().__init__(parent)
        self.window_ = window
        self.session = window.session
        self.materials = DEFAULT_MATERIALS
        self.materialCombo = QComboBox()
        for m in self.materials.materials:
            self.materialCombo.addItem(m.name)
            self.materialCombo.setItemData(self.materialCombo.count() - 1, m.description,
                                           Qt.ItemDataRole.ToolTipRole)
        self.depthSpin = QDoubleSpinBox(decimals=3, minimum=0.005, maximum=2.0,
                                        singleStep=0.01, value=0.1, suffix=" mm")
        self.rescanSpin = QSpinBox(minimum=1, maximum=200, value=10, suffix=" passes")
        self.spacingSpin = QDoubleSpinBox(decimals=3, minimum=0.02, maximum=0.5,
                                          singleStep=0.01, value=0.1, suffix=" mm")
        self.spacingSpin.setToolTip("the depth scans' lines apart (insitu engrave "
                                    "--scan-spacing)")
        self.patternLabel = QLabel("", wordWrap=True)
        self.mapButton = QPushButton("Depth map", clicked=self.depth_map)
        self.mapButton.setToolTip("the selected pattern's pocket measured in the scanned cloud "
                                  "against the top around it")
        self.measureButton = QPushButton("Measure pocket", clicked=self.measure)
        self.measureButton.setToolTip("scan the selected pattern's pocket on the rig as an "
                                      "engraving does between rounds, and map its depth")
        self.engraveButton = QPushButton("Engrave…", clicked=self.arm)
        self.engraveButton.setIcon(icon("engrave"))
        self.engraveButton.setToolTip("arm: what will be engraved, then Fire laser")
        self.resumeButton = QPushButton("Resume…", clicked=self.resume, enabled=False)
        self.resumeButton.setToolTip("go on with the engraving stopped last: the pocket "
                                     "measured first, then only the depth still missing")
        self.abortButton = QPushButton("ABORT", clicked=self.abort, enabled=False)
        self.abortButton.setIcon(icon("abort"))
        self.abortButton.setToolTip("stop at once, laser off (Esc or Space)")
        self.progressBar = QProgressBar()
        self.picture = ImageView()
        self.mapLabel = QLabel("", wordWrap=True)
        self.resultLabel = QLabel("", wordWrap=True)
        self.resultLabel.setObjectName("engraveResult")
        form = QFormLayout()
        form.addRow("Pattern", self.patternLabel)
        form.addRow("Material", self.materialCombo)
        form.addRow("Target depth", self.depthSpin)
        form.addRow("Measure every", self.rescanSpin)
        form.addRow("Scan lines apart", self.spacingSpin)
        buttons = QHBoxLayout()
        for b in (self.mapButton, self.measureButton, self.engraveButton, self.resumeButton,
                  self.abortButton):
            buttons.addWidget(b)
        lay = QVBoxLayout(self)
        lay.addLayout(form)
        lay.addLayout(buttons)
        for w in (self.progressBar, self.resultLabel, self.picture, self.mapLabel):
            lay.addWidget(w, 1 if w is self.picture else 0)
        self.arm_dialog: ArmDialog | None = None
        self._armed: _Armed | None = None
        self._running: _Armed | None = None
        self._stopped: _Armed | None = None    # the last run, stopped before its end
        self._scanning = False                  # the "scan" task running is this dock's
        self.last_map = None                # (DepthMap, DepthSummary) shown
        self.last_outcome = None
        self._bridge = _Bridge(self)
        self._bridge.measured.connect(self._measured)
        self._bridge.note.connect(self.resultLabel.setText)
        for sig in (self.session.selection_changed, self.session.plans_changed,
                    self.session.cloud_changed, self.session.rig_changed):
            sig.connect(self.refresh)
        window.runner.busy_changed.connect(lambda _n, _b: self.refresh())
        self.refresh()

    # -- state ---------------------------------------------------------------------------
    def selected(self):
        """(placement, its plan) of the selected pattern, or None (none, or not planned)."""
        s = self.session
        i = s.selected
        if not 0 <= i < len(s.placements.items) or len(s.plans) != len(s.placements.items):
            return None
        plan = s.plans[i].plan
        return None if plan is None else (s.placements.items[i], plan)

    def _busy(self) -> bool:
        from insitu.ui.qt.mark_panel import BUSY
        return any(self.window_.runner.running(n) for n in BUSY + ("depth",))

    def refresh(self) -> None:
        s, station = self.session, self.window_.station
        sel = self.selected()
        if sel is not None:
            self.patternLabel.setText(short_name(sel[0].pattern))
        else:
            self.patternLabel.setText("no cloud: scan the part first" if s.cloud is None else
                                      "select a pattern placed and checked on the cloud")
        if self._armed is not None and not self._armed.holds(sel, s.cloud, station):
            self.disarm("disarmed: the pattern, the cloud or the station changed")
        busy = self._busy()
        engraving = self.window_.runner.running("engrave")
        self._scanning &= self.window_.runner.running("scan")
        self.mapButton.setEnabled(sel is not None and not busy)
        self.measureButton.setEnabled(sel is not None and station is not None and not busy)
        self.engraveButton.setEnabled(sel is not None and station is not None and not busy
                                      and self._armed is None)
        self.resumeButton.setEnabled(self._stopped is not None and not busy
                                     and self._armed is None
                                     and self._stopped.station is station)
        self.abortButton.setEnabled(engraving or self._scanning)

    # -- the depth map -------------------------------------------------------------------
    def depth_map(self) -> None:
        """Measure the selected pattern's pocket in the session's cloud, off the GUI thread."""
        sel = self.selected()
        if sel is None or self._busy():
            return
        placement, plan = sel
        name, cloud = short_name(placement.pattern), self.session.cloud
        station = self.window_.station
        rig = None if station is None else station.rig

        def work(_p, _c, _f):
            region = pocket_region(plan, name)
            return region, measure_pocket(cloud, region, rig)
        self.resultLabel.setText("measuring the pocket…")
        self.window_.runner.start(
            "depth", work, lambda r: self.show_map(r[1], r[0], f"{name}: depth map",
                                                   None, rig is not None),
            lambda m, _c: self._said(m))

    def measure(self) -> None:
        """Scan the selected pattern's pocket on the rig and map its depth (as an engraving
        measures between rounds), off the GUI thread; ABORT (or the Scan dock's Cancel)
        stops the scan."""
        from insitu.services.pocket import scan_pocket

        sel, station = self.selected(), self.window_.station
        if sel is None or station is None or self._busy():
            return
        name = short_name(sel[0].pattern)
        try:
            region = pocket_region(sel[1], name)
        except InsituError as e:
            self._said(str(e))
            return
        spacing, cal = self.spacingSpin.value(), self.session.height_cal

        def work(progress, cancel, _f):
            return scan_pocket(station, region, spacing_mm=spacing, height_cal=cal,
                               cancel=cancel, progress=progress)
        task = self.window_.runner.start(
            "scan", work, lambda dm: self.show_map(dm, region, f"{name}: measured on the rig",
                                                   None),
            lambda m, cancelled: self._said("measuring stopped: the scan was cancelled"
                                            if cancelled else m))
        if task is not None:
            self._scanning = True
            self.resultLabel.setText("scanning the pocket…")
            task.progress.connect(self._progress)
        self.refresh()

    def show_map(self, dm, region, title: str, target_mm: float | None,
                 rig_known: bool = True, extra: str = "") -> None:
        """Show ``dm``: its picture and its numbers in words."""
        summary = DepthSummary.of(dm, target_mm)
        self.last_map = (dm, summary)
        self.picture.show_image(depth_picture(dm, region, title, target_mm), None, title)
        self.mapLabel.setText("\n".join(([extra] if extra else [])
                                        + summary.lines(rig_known)))
        if not self.window_.runner.running("engrave"):
            self.resultLabel.setText("")

    def _said(self, message: str) -> None:
        self.resultLabel.setText(message)
        self.window_.show_error(message, "engrave")

    # -- engraving -----------------------------------------------------------------------
    def report_dir(self, name: str) -> Path:
        """A new folder for the engraving's record, jobs and pictures: beside the project,
        or in the working folder of a project never saved."""
        p = self.session.project_path
        base = p.parent if p is not None else self.window_.work_folder()
        stem = "".join(ch if ch.isalnum() else "-" for ch in name)[:24].strip("-") or "pocket"
        return base / f"engrave-{stem}-{time.strftime('%Y%m%d-%H%M%S')}"

    def arm(self) -> None:
        """Arm the engraving of the selected pattern: the dialog says what will be engraved;
        nothing fires until the operator presses Fire laser."""
        from insitu.services.engrave import EngraveRequest

        sel, station = self.selected(), self.window_.station
        if sel is None or station is None or self._armed is not None or self._busy():
            return
        placement, plan = sel
        name = short_name(placement.pattern)
        try:
            region = pocket_region(plan, name)
        except InsituError as e:
            self._said(str(e))
            return
        material = self.materials.material(self.materialCombo.currentText())
        depth, every = self.depthSpin.value(), self.rescanSpin.value()
        spacing, out = self.spacingSpin.value(), self.report_dir(name)
        req = EngraveRequest(out, placement, self.session.cloud, depth, every, material.name,
                             self.materials, self.session.height_cal, spacing)
        self._open(_Armed(req, station, region))

    def resume(self) -> None:
        """Arm the engraving stopped last, to go on with it (measured first)."""
        run = self._stopped
        if run is None or self._armed is not None or self._busy():
            return
        self._open(replace(run, request=replace(run.request, resume=True)))

    def _open(self, armed: _Armed) -> None:
        """Show the arming dialog of ``armed``."""
        req = armed.request
        self._armed = armed
        rows = engrave_rows(short_name(req.placement.pattern), req.depth_mm,
                            self.materials.material(req.material), self.materials.laser,
                            req.rescan_every, req.spacing_mm,
                            " · ".join(armed.station.describe()), req.cloud.rig,
                            req.report_dir)
        if req.resume:
            rows.append(("run", "resume: the pocket is measured first, then only the depth "
                                "still missing is engraved"))
        self.arm_dialog = dlg = ArmDialog(rows, self)
        dlg.setWindowTitle("Armed: confirm to engrave")
        dlg.accepted.connect(self._fire)
        dlg.rejected.connect(lambda: self.disarm("disarmed: nothing was engraved"))
        self.resultLabel.setText("armed: confirm in the dialog (Esc disarms)")
        self.refresh()
        dlg.open()

    def disarm(self, why: str) -> None:
        dlg, self.arm_dialog, self._armed = self.arm_dialog, None, None
        if dlg is not None:
            dlg.dismiss()
        self.resultLabel.setText(why)
        self.refresh()

    def _fire(self) -> None:
        """The operator confirmed: engrave, if the pattern, cloud and station are still the
        ones armed."""
        from insitu.services.engrave import engrave

        armed, station = self._armed, self.window_.station
        if self.arm_dialog is not None:
            self.arm_dialog.deleteLater()
        self.arm_dialog, self._armed = None, None
        if armed is None or self._busy() or not armed.holds(self.selected(),
                                                             self.session.cloud, station):
            self.resultLabel.setText("disarmed: the pattern, the cloud or the station "
                                     "changed; nothing was engraved")
            self.refresh()
            return
        req, bridge = armed.request, self._bridge
        req.report_dir.parent.mkdir(parents=True, exist_ok=True)

        def work(progress, cancel, _f):
            return engrave(station, req, cancel, progress, bridge.note.emit,
                           bridge.measured.emit)
        task = self.window_.runner.start("engrave", work, self._ended, self._failed)
        if task is not None:
            self._running, self._stopped = armed, None
            self.last_outcome = None
            self.progressBar.setValue(0)
            self.resultLabel.setText("engraving: the first round…")
            task.progress.connect(self._progress)
        self.refresh()

    def _progress(self, done: int, total: int) -> None:
        self.progressBar.setMaximum(max(total, 1))
        self.progressBar.setValue(done)

    def _measured(self, dm, m: dict) -> None:
        run = self._running
        if run is None:
            return
        self.show_map(dm, run.region, f"{short_name(run.request.placement.pattern)}: after "
                      f"round {m['round']}", run.request.depth_mm, extra=measure_line(m))

    def abort(self) -> None:
        """ABORT: the board stops at once, laser off (the record keeps how far it got)."""
        if self.window_.runner.running("engrave"):
            self.window_.runner.cancel("engrave")
            self.resultLabel.setText("aborting: laser off")
        if self._scanning:
            self.window_.runner.cancel("scan")

    def _ended(self, outcome) -> None:
        run, self._running = self._running, None
        self.last_outcome = outcome
        self._tell(run, outcome.record)

    def _failed(self, message: str, cancelled: bool) -> None:
        run, self._running = self._running, None
        try:
            record = read_record(run.request.report_dir)
        except InsituError:
            record = None
        self._tell(run, record, None if cancelled else message)

    def _tell(self, run: _Armed, record, error: str | None = None) -> None:
        """How ``run`` ended, from its ``record`` (None: none written); Resume offered for
        one stopped before its end."""
        unfinished = record is not None and record.state not in ("done", "held")
        self._stopped = replace(run, request=replace(run.request, resume=False)) \
            if unfinished else None
        text = verdict(record, run.request.report_dir, error)
        self.resultLabel.setText(text)
        (self.window_.show_error if error else self.window_.show_message)(
            f"engraving: {text}", "engrave")
        self.refresh()
