"""The Calibrate dock: one guided page each for the camera, the height calibration and the
field correction — recorded on the connected rig (Record, its progress, Cancel; the height
and field pages) or a recording chosen, file out, then its verdict (pass / check / fail, its
figures in words against their limits: :mod:`insitu.ui.model.calibration_verdict`) and a
picture."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt
from PySide6.QtGui import QColor, QPixmap
from PySide6.QtWidgets import (
    QFileDialog,
    QHBoxLayout,
    QPushButton,
    QTableWidgetItem,
    QTabWidget,
    QVBoxLayout,
    QWidget,
)

from insitu.ui.model import operations as ops
from insitu.ui.model.calibration_verdict import verdict
from insitu.ui.qt.forms import load_form
from insitu.ui.qt.image_view import to_qimage
from insitu.ui.qt.image_window import Clicks, ImageWindow

LEVEL_COLOURS = {"pass": QColor(90, 200, 110), "check": QColor(240, 190, 60),
                 "fail": QColor(255, 107, 94)}
GUIDES = {
    "camera": "Record the checkerboard in several poses, with the head's axis lines drawn on "
              "it lying on the plate (insitu sim record camera-calibration). Gives the "
              "intrinsics, distortion and the camera's pose in the scan-head frame.",
    "height": "Record the flat plate at several known heights with lines at known offsets "
              "(insitu sim record height-calibration). Gives the height calibration the "
              "scan uses (Method 2).",
    "field": "Record pilot spots on the plate over the field (insitu sim record "
             "field-calibration). Gives the field correction the marking applies; the "
             "picture is the before/after report.",
}


class CalibratePage(QWidget):
    def __init__(self, window, kind: str, parent=None):
        super().__init__(parent)
        self.window_, self.kind = window, kind
        self.ui = load_form("calibrate_page", self)
        QVBoxLayout(self).addWidget(self.ui)
        ui = self.ui
        ui.guideLabel.setText(GUIDES[kind])
        ui.outputEdit.setText(f"calib/{kind}.json")
        ui.recordingBrowse.clicked.connect(self._browse_recording)
        ui.outputBrowse.clicked.connect(self._browse_output)
        ui.runButton.clicked.connect(self.run)
        self.record_button = QPushButton("Record on the rig", ui)
        self.cancel_button = QPushButton("Cancel", ui, enabled=False)
        row = QHBoxLayout()
        row.addWidget(self.record_button)
        row.addWidget(self.cancel_button)
        ui.layout().insertLayout(ui.layout().indexOf(ui.runButton), row)
        if kind in ops.RECORDED:
            self.record_button.setToolTip("record it now on the connected rig into the "
                                          "recording folder (a new one)")
            self.record_button.clicked.connect(self.record)
            self.cancel_button.clicked.connect(
                lambda: window.runner.cancel(self.record_name))
        else:
            self.record_button.setEnabled(False)
            self.record_button.setToolTip("the board is moved between views: insitu sim "
                                          "record camera-calibration")
        window.runner.busy_changed.connect(self._busy)
        self.picture: QPixmap | None = None         # the report at full size
        self.level: str | None = None               # the last verdict: pass, check, fail
        self.picture_window: ImageWindow | None = None
        self._clicks = Clicks(self)
        ui.pictureLabel.installEventFilter(self._clicks)
        self._clicks.clicked.connect(self.show_picture)

    @property
    def task_name(self) -> str:
        return f"calibrate-{self.kind}"

    @property
    def record_name(self) -> str:
        return f"record-{self.kind}"

    def record(self) -> None:
        """Record the calibration on the connected rig into the recording folder (default
        calib/KIND-recording beside the project), off the GUI thread."""
        w, station = self.window_, self.window_.station
        busy = [n for n in ("scan", "mark", "preview", "produce") if w.runner.running(n)]
        if station is None or busy:
            self.ui.notesLabel.setText("connect the rig first" if station is None else
                                       f"the station is busy ({busy[0]})")
            return
        folder = Path(self.ui.recordingEdit.text().strip() or f"calib/{self.kind}-recording")
        if not folder.is_absolute() and w.session.project_path is not None:
            folder = w.session.project_path.parent / folder
        kind = self.kind
        task = w.runner.start(self.record_name, lambda p, c, _f: ops.record_calibration(
            station, kind, folder, p, c), self._recorded, self._failed)
        if task is not None:
            self.ui.notesLabel.setText(f"recording into {folder}…")
            self.ui.progressBar.setValue(0)
            task.progress.connect(lambda d, t: (self.ui.progressBar.setMaximum(t),
                                                self.ui.progressBar.setValue(d)))

    def _recorded(self, folder: Path) -> None:
        self.ui.recordingEdit.setText(str(folder))
        self.ui.notesLabel.setText(f"recorded {folder}: Calibrate fits it")

    def _browse_recording(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, f"Recorded {self.kind} calibration")
        if folder:
            self.ui.recordingEdit.setText(folder)

    def _browse_output(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Save the calibration", "", "JSON (*.json)")
        if path:
            self.ui.outputEdit.setText(path)

    def run(self) -> None:
        rec, out = self.ui.recordingEdit.text().strip(), self.ui.outputEdit.text().strip()
        if not rec or not out:
            self.window_.show_error(f"{self.kind} calibration: choose the recording and the "
                                    "file to save")
            return
        out_path = Path(out).expanduser()
        if not out_path.is_absolute() and self.window_.session.project_path is not None:
            out_path = self.window_.session.project_path.parent / out_path
        out_path.parent.mkdir(parents=True, exist_ok=True)
        kind = self.kind
        task = self.window_.runner.start(
            self.task_name, lambda progress, _c, _f: ops.calibrate(kind, Path(rec), out_path,
                                                                   progress),
            self._done, self._failed)
        if task is not None:
            self.ui.notesLabel.setText("calibrating…")
            task.progress.connect(lambda d, t: (self.ui.progressBar.setMaximum(t),
                                                self.ui.progressBar.setValue(d)))

    def _done(self, outcome: ops.CalibrationOutcome) -> None:
        ui = self.ui
        level, line, rows = verdict(self.kind, outcome.residuals)
        self.level = level
        ui.notesLabel.setText(f"{line}\nwrote {outcome.path}: {outcome.notes}")
        ui.notesLabel.setStyleSheet(f"color: {LEVEL_COLOURS[level].name()};")
        table = ui.residualsTable
        table.setColumnCount(4)
        table.setHorizontalHeaderLabels(["figure", "value", "limit", "verdict"])
        table.setRowCount(len(rows))
        for r, row in enumerate(rows):
            for c, text in enumerate((row.name, row.value, row.limit, row.level)):
                item = QTableWidgetItem(text)
                if row.level:
                    item.setForeground(LEVEL_COLOURS[row.level])
                table.setItem(r, c, item)
        table.resizeColumnsToContents()
        self.picture = pix = QPixmap.fromImage(to_qimage(outcome.picture))
        ui.pictureLabel.setPixmap(pix.scaled(ui.pictureLabel.width(), 240, Qt.KeepAspectRatio,
                                             Qt.SmoothTransformation))
        ui.pictureLabel.setToolTip("click: the picture at full size, with zoom")
        ui.pictureLabel.setCursor(Qt.CursorShape.PointingHandCursor)
        self.picture_name = outcome.path.with_suffix(".png").name
        self.window_.calibration_done(self.kind, outcome.path)

    def show_picture(self) -> None:
        """The report picture at full size in a zoomable window (nothing before one)."""
        if self.picture is None:
            return
        if self.picture_window is not None:
            self.picture_window.close()
        self.picture_window = ImageWindow(self.picture, f"{self.kind} calibration — "
                                                        f"{self.picture_name}", self)
        self.picture_window.show()

    def _failed(self, message: str, _cancelled: bool) -> None:
        self.ui.notesLabel.setText(message)
        self.window_.show_error(message)

    def _busy(self, name: str, busy: bool) -> None:
        if name == self.task_name:
            self.ui.runButton.setEnabled(not busy)
        if name == self.record_name:
            self.record_button.setEnabled(not busy)
            self.cancel_button.setEnabled(busy)


class CalibratePanel(QTabWidget):
    def __init__(self, window, parent=None):
        super().__init__(parent)
        self.pages = {k: CalibratePage(window, k) for k in ("camera", "height", "field")}
        for kind, page in self.pages.items():
            self.addTab(page, kind.capitalize())
