"""Pens in the application: the pens editor (a table, one row per pen, opened from the Mark
dock), the pen chooser of the selected placement (Place dock) and the Mark dock's line
naming the pens in use. Every edit is checked as a pens file is (one line naming the pen and
the field) and goes to the session, which plans the placements again."""

from __future__ import annotations

from pathlib import Path

from pydantic import ValidationError
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QFileDialog,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from insitu.errors import InsituError
from insitu.formats.pens import Pen, read_pens, write_pens
from insitu.formats.validation import validation_message

PENS_FILES = "insitu pens (*.json)"
CHOOSER_TIP = "The pen (laser set) this pattern is marked with"
EDIT_TIP = "Edit the pens: power, frequency, speeds, passes, delays, wobble"
LOCKED = "pens cannot change while a job marks: it runs with the pens it was armed with"
COLUMNS: tuple[tuple[str, str], ...] = (
    ("Name", "name"), ("Colour", "colour"), ("Power %", "power_pct"),
    ("Frequency kHz", "frequency_khz"), ("Speed mm/s", "mark_speed_mm_s"),
    ("Jump mm/s", "jump_speed_mm_s"), ("Passes", "passes"),
    ("Laser on µs", "delays_us.laser_on"), ("Laser off µs", "delays_us.laser_off"),
    ("Jump µs", "delays_us.jump"), ("Mark µs", "delays_us.mark"),
    ("Polygon µs", "delays_us.polygon"), ("Wobble mm", "wobble.amplitude_mm"),
    ("Wobble Hz", "wobble.frequency_hz"))
"""(header, field of :class:`~insitu.formats.pens.Pen`; ``a.b`` inside its object). A
wobble of 0 mm is off; a wobble given as a pitch shows its frequency at the pen's speed."""


def pen_cells(pen: Pen) -> list[str]:
    """The texts of ``pen``'s row."""
    d = pen.model_dump(mode="json")
    w = pen.wobble
    d["wobble"] = ({"amplitude_mm": 0, "frequency_hz": 0} if w is None else
                   {"amplitude_mm": w.amplitude_mm, "frequency_hz": w.hz(pen.mark_speed_mm_s)})
    out = []
    for _, key in COLUMNS:
        v = d
        for k in key.split("."):
            v = v[k]
        out.append(f"{v:g}" if isinstance(v, float) else str(v))
    return out


def pen_from_cells(cells: list[str], where: str) -> Pen:
    """A pen from a row's texts; InsituError ``where: pens[…] ('name').field: …``."""
    d: dict = {}
    for (_, key), text in zip(COLUMNS, cells):
        head, _, tail = key.partition(".")
        value = text.strip() if head in ("name", "colour") else _number(text)
        if tail:
            d.setdefault(head, {})[tail] = value
        else:
            d[head] = value
    if d["wobble"]["amplitude_mm"] in (0, "0"):
        d["wobble"] = None
    try:
        return Pen.model_validate(d)
    except ValidationError as e:
        raise InsituError(validation_message(where, e, f"pen {d.get('name')!r}")) from None


def _number(text: str):
    try:
        v = float(text)
    except ValueError:
        return text.strip()
    return int(v) if v.is_integer() else v


class PensEditor(QDialog):
    """The pen table: edit a cell (checked at once), add, remove, make the default, import
    and export a pens file. Changes go to ``session.set_pens``."""

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Pens")
        self.session = session
        self.table = QTableWidget(0, len(COLUMNS), self)
        self.table.setHorizontalHeaderLabels([h for h, _ in COLUMNS])
        self.table.horizontalHeader().setSectionResizeMode(QHeaderView.ResizeToContents)
        self.table.itemChanged.connect(self._edited)
        self.error = QLabel(self)
        self.error.setWordWrap(True)
        self.error.setProperty("warning", True)
        buttons = QHBoxLayout()
        for text, slot in (("Add", self.add), ("Remove", self.remove),
                           ("Make default", self.make_default), ("Import…", self._import),
                           ("Export…", self._export)):
            b = QPushButton(text, self)
            b.clicked.connect(slot)
            buttons.addWidget(b)
            setattr(self, text.rstrip("…").lower().replace(" ", "_") + "_button", b)
        lay = QVBoxLayout(self)
        lay.addWidget(self.table)
        lay.addLayout(buttons)
        lay.addWidget(self.error)
        self.resize(1100, 300)
        session.pens_changed.connect(self.refresh)
        self._filling = False
        self.refresh()

    def set_locked(self, locked: bool) -> None:
        """While a job marks: the table and its buttons greyed, saying why."""
        self.table.setEnabled(not locked)
        for b in (self.add_button, self.remove_button, self.make_default_button,
                  self.import_button):
            b.setEnabled(not locked)
        self.error.setText(LOCKED if locked else "")

    def refresh(self) -> None:
        self._filling = True
        try:
            pens = self.session.pens
            self.table.setRowCount(len(pens.pens))
            for r, pen in enumerate(pens.pens):
                for c, text in enumerate(pen_cells(pen)):
                    item = QTableWidgetItem(text)
                    if COLUMNS[c][1] == "name" and pen.name == pens.default:
                        item.setToolTip("the default pen")
                        font = item.font()
                        font.setBold(True)
                        item.setFont(font)
                    if COLUMNS[c][1] == "colour":
                        item.setBackground(QColor(pen.colour))
                    self.table.setItem(r, c, item)
        finally:
            self._filling = False

    def _row(self, r: int) -> list[str]:
        return [self.table.item(r, c).text() for c in range(len(COLUMNS))]

    def _edited(self, item: QTableWidgetItem) -> None:
        if self._filling:
            return
        r = item.row()
        old = self.session.pens.pens[r].name
        try:
            pen = pen_from_cells(self._row(r), "pens")
            if pen.name != old and pen.name in self.session.pens.names:
                raise InsituError(f"pens: pen {pen.name!r} exists already")
        except InsituError as e:
            self.error.setText(str(e))
            self.refresh()                               # back to the valid pen
            return
        self.error.setText("")
        self.session.set_pens(self.session.pens.replaced(pen, old), (old, pen.name))

    def add(self) -> None:
        """A new pen, a copy of the selected one (or the default) under a new name."""
        pens = self.session.pens
        r = self.table.currentRow()
        base = pens.pens[r] if 0 <= r < len(pens.pens) else pens.pen(None)
        n = 1
        while f"pen {n}" in pens.names:
            n += 1
        self.session.set_pens(pens.replaced(base.model_copy(update={"name": f"pen {n}"})))

    def remove(self) -> None:
        pens, r = self.session.pens, self.table.currentRow()
        if not 0 <= r < len(pens.pens) or len(pens.pens) == 1:
            self.error.setText("pens: the last pen stays" if len(pens.pens) == 1 else "")
            return
        rest = tuple(p for i, p in enumerate(pens.pens) if i != r)
        default = pens.default if pens.default in {p.name for p in rest} else rest[0].name
        self.session.set_pens(type(pens)(default=default, pens=rest))

    def make_default(self) -> None:
        pens, r = self.session.pens, self.table.currentRow()
        if 0 <= r < len(pens.pens):
            self.session.set_pens(pens.model_copy(update={"default": pens.pens[r].name}))

    def _import(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Import pens", "", PENS_FILES)
        if path:
            self.load(Path(path))

    def load(self, path: Path) -> None:
        try:
            self.session.set_pens(read_pens(path))
        except InsituError as e:
            self.error.setText(str(e))

    def _export(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Export pens", "pens.json", PENS_FILES)
        if path:
            write_pens(path, self.session.pens)


class PenChooser(QComboBox):
    """The selected placement's pen (undoable: a placement change)."""

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        self.setToolTip(CHOOSER_TIP)
        for sig in (session.pens_changed, session.selection_changed,
                    session.placements.changed):
            sig.connect(self.refresh)
        self.currentIndexChanged.connect(self._chosen)
        self._filling = False
        self.locked = False
        self.refresh()

    def set_locked(self, locked: bool) -> None:
        """No pen is chosen while a job marks (the job runs with the pens it was armed
        with)."""
        self.locked = locked
        self.refresh()

    def refresh(self) -> None:
        self._filling = True
        try:
            self.clear()
            pens = self.session.pens
            for p in pens.pens:
                self.addItem(p.name + (" (default)" if p.name == pens.default else ""), p.name)
                self.setItemData(self.count() - 1, QColor(p.colour), Qt.DecorationRole)
                self.setItemData(self.count() - 1, p.summary(), Qt.ToolTipRole)
            current = self.session.current()
            self.setEnabled(current is not None and not self.locked)
            self.setToolTip(LOCKED if self.locked else CHOOSER_TIP)
            if current is not None:
                self.setCurrentIndex(pens.names.index(self.session.pen_of(current).name))
        finally:
            self._filling = False

    def _chosen(self, index: int) -> None:
        if self._filling or index < 0 or self.session.current() is None:
            return
        name = self.itemData(index)
        self.session.update_selected(pen=None if name == self.session.pens.default
                                     and self.session.current().pen is None else name)


def add_pen_chooser(form, session, parent: QWidget) -> PenChooser:
    """A "Pen" row with a :class:`PenChooser` at the end of the Place dock's ``form``."""
    chooser = PenChooser(session, parent)
    form.addRow("Pen", chooser)
    return chooser


class PensRow(QWidget):
    """The Mark dock's row: the pens the placements use, and "Pens…" opening the editor."""

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        self.label = QLabel(self)
        self.label.setWordWrap(True)
        self.button = QPushButton("Pens…", self)
        self.button.setToolTip(EDIT_TIP)
        self.locked = False
        self.button.clicked.connect(self.open_editor)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        lay.addWidget(self.label, 1)
        lay.addWidget(self.button)
        self.editor: PensEditor | None = None
        for sig in (session.pens_changed, session.placements.changed):
            sig.connect(self.refresh)
        self.refresh()

    def refresh(self) -> None:
        s = self.session
        used = dict.fromkeys(s.pen_of(p).name for p in s.placements.items)
        self.label.setText("pens: " + (", ".join(f"{n} ({s.pens.pen(n).summary()})"
                                                 for n in used) or "none used yet"))

    def set_locked(self, locked: bool) -> None:
        """While a job marks, the pens are not edited (the editor shows them, greyed)."""
        self.button.setToolTip(LOCKED if locked else EDIT_TIP)
        if self.editor is not None:
            self.editor.set_locked(locked)
        self.locked = locked

    def open_editor(self) -> PensEditor:
        if self.editor is None:
            self.editor = PensEditor(self.session, self)
            self.editor.set_locked(self.locked)
        self.editor.show()
        self.editor.raise_()
        return self.editor
