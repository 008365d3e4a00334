"""The Place dock: the placed patterns, importing them (file, text, QR), their exact values
(centre, width, rotation, projection, hatch) and the outcome of the checks. Every change goes
through the session's undoable placement history."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import QFileDialog, QInputDialog, QSizePolicy, QVBoxLayout, QWidget

from insitu.errors import InsituError
from insitu.marking import PROJECTIONS, Placement
from insitu.patterns import FILE_SUFFIXES, is_spec
from insitu.ui.model.free_spot import free_spot
from insitu.ui.model.scene_data import base_pattern, code_hatch, handles
from insitu.ui.qt.forms import load_form
from insitu.ui.qt.pens_panel import add_pen_chooser

REFUSED_COLOUR = "#ff6b5e"
PATTERN_FILES = f"Patterns ({' '.join('*' + s for s in FILE_SUFFIXES)})"


def short_name(spec: str) -> str:
    return spec if is_spec(spec) else Path(spec).name


def _loads(p: Placement) -> bool:
    try:
        handles(p)
    except InsituError:
        return False
    return True

STATUS_LINES = 6
"""Lines of the verdict the Place dock shows; its tooltip holds them all."""


class PlacePanel(QWidget):
    def __init__(self, window, parent=None):
        super().__init__(parent)
        self.window_ = window
        self.session = window.session
        self.ui = load_form("place", self)
        QVBoxLayout(self).addWidget(self.ui)
        ui = self.ui
        ui.importButton.clicked.connect(self._import)
        ui.textButton.clicked.connect(lambda: self._ask("Text to mark", "text"))
        ui.qrButton.clicked.connect(lambda: self._ask("QR code content", "qr"))
        ui.removeButton.clicked.connect(self.session.remove_selected)
        ui.patternList.currentRowChanged.connect(self.session.select)
        fields = {ui.xSpin: "x", ui.ySpin: "y", ui.widthSpin: "width_mm",
                  ui.rotateSpin: "rotate_deg", ui.hatchSpin: "hatch_mm",
                  ui.hatchAngleSpin: "hatch_angle_deg"}
        for spin, name in fields.items():
            spin.setKeyboardTracking(False)
            spin.valueChanged.connect(lambda _v, n=name: self._edited(n))
        for i, (name, mode) in enumerate(PROJECTIONS.items()):
            ui.modeCombo.addItem(name)
            ui.modeCombo.setItemData(i, mode.description, Qt.ItemDataRole.ToolTipRole)
        ui.modeCombo.currentIndexChanged.connect(lambda _i: self._edited("mode"))
        ui.hatchCheck.toggled.connect(lambda _b: self._edited("hatch_mm"))
        ui.crossCheck.toggled.connect(lambda _b: self._edited("cross"))
        self.pen_chooser = add_pen_chooser(ui.placeBox.layout(), self.session, ui.placeBox)
        self.session.placements.changed.connect(self.refresh)
        self.session.selection_changed.connect(self.refresh)
        self.session.plans_changed.connect(self.show_outcome)
        label = ui.statusLabel      # a verdict of any length (a long path in it) moves nothing
        label.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Fixed)
        label.setFixedHeight(label.fontMetrics().lineSpacing() * STATUS_LINES + 4)
        label.setAlignment(Qt.AlignmentFlag.AlignTop | Qt.AlignmentFlag.AlignLeft)
        self._refreshing = False
        self.refresh()

    # -- adding --------------------------------------------------------------------------
    def add_pattern(self, spec: str) -> bool:
        """Place pattern ``spec`` (file, ``text:"…"``, ``qr:"…"``) on the part's free top
        (:func:`~insitu.ui.model.free_spot.free_spot`: the highest flat level, off walls,
        holes and the other patterns, nearest the view's centre), a third of the cloud's
        width wide or as much as fits there; without a cloud at the view's centre. False
        (and a message) if it cannot be loaded."""
        try:
            size = base_pattern(spec).size
        except InsituError as e:
            self.window_.show_error(str(e), "place")
            return False
        centre = self.window_.view.camera.centre
        at, width = (round(float(centre[0]), 1), round(float(centre[1]), 1)), 10.0
        cloud = self.session.cloud
        if cloud is not None and len(cloud):
            lo, hi = cloud.points[:, :2].min(0), cloud.points[:, :2].max(0)
            width = round(max(float(min(hi - lo)) / 3, 1.0), 1)
            aspect = float(np.hypot(1.0, size[1] / size[0])) if size[0] > 0 else 1.0
            taken = [handles(p).corners for p in self.session.placements.items
                     if _loads(p)]
            spot = free_spot(cloud.points, taken, width * aspect / 2, at)
            if spot is not None:
                at = spot.xy
                width = round(max(min(width, 2 * spot.room_mm / aspect), 1.0), 1)
        placement = Placement(spec, at, width)
        hatch = code_hatch(placement)
        if hatch is not None:  # a code is hatched along its modules: an outline does not read
            placement = replace(placement, hatch_mm=hatch[0], hatch_angle_deg=hatch[1])
        self.session.add_placement(placement)
        self.window_.clear_message("place")
        return True

    def _import(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Import a pattern", "", PATTERN_FILES)
        if path:
            self.add_pattern(path)

    def _ask(self, title: str, kind: str) -> None:
        text, ok = QInputDialog.getText(self, title, title + ":")
        if ok and text.strip():
            self.add_pattern(f'{kind}:"{text.strip()}"')

    # -- editing -------------------------------------------------------------------------
    def _edited(self, name: str) -> None:
        if self._refreshing or self.session.current() is None:
            return
        ui = self.ui
        if name in ("x", "y"):
            change = {"at_mm": (ui.xSpin.value(), ui.ySpin.value())}
        elif name == "hatch_mm":
            change = {"hatch_mm": ui.hatchSpin.value() if ui.hatchCheck.isChecked() else None}
        elif name == "mode":
            change = {"mode": ui.modeCombo.currentText()}
        elif name == "cross":
            change = {"cross": ui.crossCheck.isChecked()}
        else:
            change = {name: getattr(ui, {"width_mm": "widthSpin", "rotate_deg": "rotateSpin",
                                         "hatch_angle_deg": "hatchAngleSpin"}[name]).value()}
        self.session.update_selected(**change)

    def refresh(self) -> None:
        """Show the session's placements and the selected one's values."""
        self._refreshing = True
        try:
            ui, items = self.ui, self.session.placements.items
            ui.patternList.blockSignals(True)
            ui.patternList.clear()
            ui.patternList.addItems([short_name(p.pattern) for p in items])
            ui.patternList.setCurrentRow(self.session.selected)
            ui.patternList.blockSignals(False)
            p = self.session.current()
            ui.placeBox.setEnabled(p is not None)
            ui.removeButton.setEnabled(p is not None)
            if p is not None:
                ui.xSpin.setValue(p.at_mm[0])
                ui.ySpin.setValue(p.at_mm[1])
                ui.widthSpin.setValue(p.width_mm)
                ui.rotateSpin.setValue(p.rotate_deg)
                ui.modeCombo.setCurrentText(p.mode)
                ui.hatchCheck.setChecked(p.hatch_mm is not None)
                if p.hatch_mm is not None:
                    ui.hatchSpin.setValue(p.hatch_mm)
                ui.hatchAngleSpin.setValue(p.hatch_angle_deg)
                ui.crossCheck.setChecked(p.cross)
        finally:
            self._refreshing = False
        self.show_outcome()

    def show_outcome(self) -> None:
        """The selected placement's verdict as ``insitu mark`` gives it: its size and time, or
        why it is refused, then every finding (walls, codes, the loader's warnings, the rig;
        :meth:`insitu.services.plan.PlanOutcome.lines`)."""
        s, label = self.session, self.ui.statusLabel
        i = s.selected
        if not 0 <= i < len(s.plans):
            text, warn = ("" if s.current() is None else "checking…"), False
        else:
            outcome = s.plans[i]
            lines = outcome.lines()
            if outcome.plan is not None:
                plan = outcome.plan
                z = plan.projection.points[:, 2]
                lines.insert(0, f"OK: {len(plan.job.paths)} paths on z {z.min():.2f} … "
                                f"{z.max():.2f} mm, about {plan.estimate.total_s:.1f} s")
            text, warn = "\n".join(lines), outcome.plan is None or bool(outcome.warnings)
        label.setText(text)
        label.setToolTip(text)                  # every line, where the label clips them
        for row in range(self.ui.patternList.count()):      # each refusal on its row
            item = self.ui.patternList.item(row)
            error = s.plans[row].error if row < len(s.plans) else None
            item.setForeground(QBrush(QColor(REFUSED_COLOUR)) if error else QBrush())
            item.setToolTip(f"refused: {error}" if error else "")
        label.setProperty("warning", warn)
        label.style().unpolish(label)
        label.style().polish(label)
