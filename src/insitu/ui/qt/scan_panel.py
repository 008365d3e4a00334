"""The Scan dock: source (rig or recording), height calibration, region, spacing, exposure;
Scan / Cancel, progress and the summary. The scan runs on a worker; each frame goes to the
camera dock and its points to the 3-D view."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QFileDialog, QVBoxLayout, QWidget

from insitu.formats.project import ScanSettings
from insitu.ui.model import operations as ops
from insitu.ui.model.operations import NO_RIG
from insitu.ui.qt.forms import load_form


class ScanPanel(QWidget):
    """``window``: the main window (session, runner, station, camera image, messages)."""

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
        live, busy = self.ui.sourceCombo.currentIndex() == 0, w.runner.running("scan")
        no_rig = live and w.station is None
        self.ui.scanButton.setEnabled(not busy and not no_rig)
        self.ui.scanButton.setToolTip(NO_RIG if no_rig else "")
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
        w.session.set_cloud(None)
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
        self.window_.show_message(f"scan done: {s.points:,} points")

    def _failed(self, message: str, cancelled: bool) -> None:
        """Show why; a cancel or a device fault keeps the lines measured before it."""
        task = self.window_.runner.tasks.get("scan")
        partial = getattr(task.error, "partial", None) if task is not None else None
        if partial is not None:
            self.window_.session.set_cloud(partial.cloud)
            message += f" (kept {len(partial.cloud):,} points measured before)"
        self.ui.summaryLabel.setText(message)
        self.window_.show_error(message, "scan")

    def _busy(self, name: str, busy: bool) -> None:
        if name == "scan":
            self._can_scan()
            self.ui.cancelButton.setEnabled(busy)
