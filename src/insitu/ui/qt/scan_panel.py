"""The Scan dock: source (rig or recording), height calibration, region, spacing, exposure;
Scan / Cancel, progress and the summary. The scan runs on a worker; each frame goes to the
camera dock and its points to the 3-D view. The session's cloud is replaced only by a scan
that finished (one undo step): a cancelled or failed one leaves it as it was and offers the
lines it measured beside it (Use the partial cloud)."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QAbstractSpinBox,
    QCheckBox,
    QComboBox,
    QFileDialog,
    QLineEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from insitu.formats.project import ScanSettings
from insitu.ui.model import operations as ops
from insitu.ui.model.operations import NO_RIG
from insitu.ui.qt.forms import load_form

BUSY = ("scan", "mark", "preview", "produce", "engrave")
"""Tasks that use the station: a scan waits for them."""
CONNECTING = "the rig is connecting…"


class ScanPanel(QWidget):
    """``window``: the main window (session, runner, station, camera image, messages).
    ``settings_changed``: a setting a project keeps was edited. ``partial``: the lines a
    cancelled or failed scan measured (a ScanResult; None: none offered)."""

    settings_changed = Signal()

    def __init__(self, window, parent=None):
        super().__init__(parent)
        self.window_ = window
        self.ui = load_form("scan", self)
        QVBoxLayout(self).addWidget(self.ui)
        ui = self.ui
        ui.scanButton.clicked.connect(self.start)
        ui.cancelButton.clicked.connect(lambda: window.runner.cancel("scan"))
        ui.wholePartCheck.toggled.connect(self._region_enabled)
        ui.replayBrowse.clicked.connect(self._browse_replay)
        ui.heightCalBrowse.clicked.connect(self._browse_height_cal)
        ui.heightCalEdit.editingFinished.connect(
            lambda: window.load_height_cal(self._path(ui.heightCalEdit.text())))
        ui.sourceCombo.currentIndexChanged.connect(self._source_changed)
        self.partial = None
        self.partial_button = QPushButton("", ui)
        self.partial_button.setObjectName("partialButton")
        self.partial_button.setToolTip("make the lines measured before the scan stopped the "
                                       "session's cloud (Undo brings the cloud back)")
        self.partial_button.clicked.connect(self.use_partial)
        self.partial_button.hide()
        ui.layout().insertWidget(ui.layout().indexOf(ui.summaryLabel) + 1, self.partial_button)
        for w in ui.findChildren(QAbstractSpinBox):
            w.editingFinished.connect(self.settings_changed.emit)
        for w in ui.findChildren(QLineEdit):
            w.editingFinished.connect(self.settings_changed.emit)
        for w in ui.findChildren(QCheckBox):
            w.toggled.connect(lambda _b: self.settings_changed.emit())
        for w in ui.findChildren(QComboBox):
            w.currentIndexChanged.connect(lambda _i: self.settings_changed.emit())
        self._region_enabled(True)
        window.session.rig_changed.connect(self._can_scan)
        self._source_changed(0)
        window.runner.busy_changed.connect(self._busy)

    # -- settings ------------------------------------------------------------------------
    @staticmethod
    def _path(text: str) -> Path | None:
        return Path(text.strip()).expanduser() if text.strip() else None

    def settings(self) -> ScanSettings:
        ui = self.ui
        region = None if ui.wholePartCheck.isChecked() else (
            ui.x0Spin.value(), ui.x1Spin.value(), ui.y0Spin.value(), ui.y1Spin.value())
        replay = self._path(ui.replayEdit.text()) if ui.sourceCombo.currentIndex() == 1 else None
        return ScanSettings(region, ui.spacingSpin.value(), ui.exposureSpin.value(), replay,
                            ui.speedSpin.value())

    def show_settings(self, s: ScanSettings) -> None:
        ui = self.ui
        ui.sourceCombo.setCurrentIndex(1 if s.replay is not None else 0)
        ui.replayEdit.setText(str(s.replay) if s.replay else "")
        ui.wholePartCheck.setChecked(s.region is None)
        if s.region is not None:
            self.set_region(s.region)
        ui.spacingSpin.setValue(s.spacing_mm)
        ui.exposureSpin.setValue(s.exposure_ms)
        ui.speedSpin.setValue(s.speed_mm_s)

    def set_region(self, region) -> None:
        """Show ``region`` (x0, x1, y0, y1) mm, e.g. drawn in the 3-D view."""
        ui = self.ui
        ui.wholePartCheck.setChecked(False)
        for spin, v in zip((ui.x0Spin, ui.x1Spin, ui.y0Spin, ui.y1Spin), region):
            spin.setValue(v)
        ui.sourceCombo.setCurrentIndex(0)

    def _region_enabled(self, whole: bool) -> None:
        for spin in (self.ui.x0Spin, self.ui.x1Spin, self.ui.y0Spin, self.ui.y1Spin):
            spin.setEnabled(not whole)

    def _source_changed(self, index: int) -> None:
        live = index == 0
        for w in (self.ui.regionBox, self.ui.settingsBox):
            w.setEnabled(live)
        for w in (self.ui.replayEdit, self.ui.replayBrowse):
            w.setEnabled(not live)
        self._can_scan()

    def _can_scan(self) -> None:
        """Scan is enabled when it can run — a recording, or the rig connected (the window's
        station: the one truth the status bar shows too); a refusal that no longer holds
        goes."""
        w = self.window_
        live = self.ui.sourceCombo.currentIndex() == 0
        busy = [n for n in BUSY if w.runner.running(n)]
        no_rig = live and w.station is None
        self.ui.scanButton.setEnabled(not busy and not no_rig)
        self.ui.scanButton.setToolTip(
            (CONNECTING if w.connecting else NO_RIG) if no_rig else
            f"waits while the station is busy ({busy[0]})" if busy else "")
        if not no_rig and self.ui.summaryLabel.text() == NO_RIG:
            self.ui.summaryLabel.setText("")
            w.clear_message("scan")

    def _browse_replay(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Recorded scan folder")
        if folder:
            self.ui.replayEdit.setText(folder)
            self.ui.sourceCombo.setCurrentIndex(1)

    def _browse_height_cal(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Height calibration", "",
                                              "Height calibration (*.json)")
        if path:
            self.ui.heightCalEdit.setText(path)
            self.window_.load_height_cal(Path(path))

    # -- run -----------------------------------------------------------------------------
    def start(self) -> None:
        w = self.window_
        settings = self.settings()
        if settings.region is not None and not (settings.region[0] < settings.region[1]
                                                and settings.region[2] < settings.region[3]):
            w.show_error("region: expected x0 < x1 and y0 < y1")
            return
        station, cal = w.station, w.session.height_cal
        task = w.runner.start("scan", lambda progress, cancel, frame: ops.scan(
            station, settings, cal, progress, cancel, frame), self._done, self._failed)
        if task is None:
            return
        self.offer_partial(None)
        w.view.set_cloud(None)              # the new cloud grows here; the session keeps its
        w.clear_message("scan")
        self.ui.progressBar.setValue(0)
        self.ui.summaryLabel.setText("scanning…")
        task.progress.connect(self._progress)
        task.frame.connect(self._frame)

    def _progress(self, done: int, total: int) -> None:
        self.ui.progressBar.setMaximum(total)
        self.ui.progressBar.setValue(done)

    def _frame(self, image, centres, points) -> None:
        self.window_.camera_image.show_image(image, centres, "scan: line centres")
        if len(points):
            self.window_.session.live_points_added.emit(points)

    def _done(self, result) -> None:
        s = result.summary
        self.window_.session.set_cloud(result.cloud)
        self.ui.summaryLabel.setText(
            f"{s.points:,} points from {s.frames_with_line} of {s.frames} lines ({s.method}), "
            f"z {s.bounds_min[2]:.2f} … {s.bounds_max[2]:.2f} mm, {s.seconds:.1f} s")
        self.window_.show_message(f"scan done: {s.points:,} points", "scan")

    def _failed(self, message: str, cancelled: bool) -> None:
        """Show why; the session's cloud stays as it was (shown again), the lines measured
        before are offered beside it — taken at once when there was no cloud to keep."""
        w = self.window_
        task = w.runner.tasks.get("scan")
        partial = getattr(task.error, "partial", None) if task is not None else None
        w.binding.show_cloud()
        if partial is not None and len(partial.cloud):
            if w.session.cloud is None:
                w.session.set_cloud(partial.cloud)
                message += f" (kept {len(partial.cloud):,} points measured before)"
            else:
                self.offer_partial(partial)
                message += " (the cloud before it is kept)"
        self.ui.summaryLabel.setText(message)
        w.show_error(message, "scan")

    def offer_partial(self, partial) -> None:
        """Offer ``partial`` (a ScanResult) beside the session's cloud; None: nothing."""
        self.partial = partial
        self.partial_button.setVisible(partial is not None)
        if partial is not None:
            lines = max(self.ui.progressBar.maximum(), partial.summary.frames)
            self.partial_button.setText(f"Use the partial cloud ({len(partial.cloud):,} "
                                        f"points, {partial.summary.frames} of {lines} lines)")

    def use_partial(self) -> None:
        """The partial cloud becomes the session's (Undo brings back the one before)."""
        if self.partial is not None:
            self.window_.session.set_cloud(self.partial.cloud)
            self.window_.show_message("the partial cloud is the session's cloud (Undo brings "
                                      "back the one before)", "scan")
            self.offer_partial(None)

    def _busy(self, name: str, busy: bool) -> None:
        if name in BUSY:
            self._can_scan()
        if name == "scan":
            self.ui.cancelButton.setEnabled(busy)
