"""The questions the window asks before something that cannot be undone: arm the laser
(what will be marked, confirmed by the operator), save unsaved changes (Save / Discard /
Cancel), abort a marking under way before quitting."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QMessageBox,
    QVBoxLayout,
    QWidget,
)

FIRE_TEXT = "Fire laser"


class ArmDialog(QDialog):
    """The armed job, shown as (label, value) ``rows``: nothing is sent until the operator
    presses *Fire laser* (``accepted``); Cancel, Esc or closing disarms (``rejected``). The
    fire button is not the default: Enter does not fire."""

    def __init__(self, rows: list[tuple[str, str]], parent: QWidget | None = None):
        super().__init__(parent)
        self.setWindowTitle("Armed: confirm to mark")
        self.setWindowModality(Qt.WindowModality.WindowModal)
        self.setMinimumWidth(520)
        lay = QVBoxLayout(self)
        head = QLabel("The laser is armed. Check what will be marked, then fire or cancel.")
        head.setWordWrap(True)
        lay.addWidget(head)
        form = QFormLayout()
        for label, value in rows:
            v = QLabel(value)
            v.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            v.setWordWrap(True)
            form.addRow(label, v)
        lay.addLayout(form)
        self.rows = rows
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Cancel)
        self.fire_button = buttons.addButton(FIRE_TEXT, QDialogButtonBox.ButtonRole.AcceptRole)
        self.fire_button.setObjectName("fireButton")
        self.fire_button.setAutoDefault(False)
        self.fire_button.setDefault(False)
        cancel = buttons.button(QDialogButtonBox.StandardButton.Cancel)
        cancel.setDefault(True)
        cancel.setFocus()
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        lay.addWidget(buttons)

    def dismiss(self) -> None:
        """Close without a signal: the owner has already forgotten the armed job."""
        self.blockSignals(True)
        self.reject()
        self.deleteLater()


def ask_save(parent: QWidget, changes: list[str], what: str) -> str:
    """Ask whether to save unsaved ``changes`` before ``what`` ("quitting", "opening …");
    returns "save", "discard" or "cancel"."""
    box = QMessageBox(QMessageBox.Icon.Warning, "Unsaved changes",
                      f"The session has unsaved changes ({', '.join(changes)}). Save them "
                      f"before {what}?", QMessageBox.StandardButton.Save
                      | QMessageBox.StandardButton.Discard | QMessageBox.StandardButton.Cancel,
                      parent)
    box.setDefaultButton(QMessageBox.StandardButton.Save)
    box.setEscapeButton(QMessageBox.StandardButton.Cancel)
    answer = box.exec()
    return {QMessageBox.StandardButton.Save: "save",
            QMessageBox.StandardButton.Discard: "discard"}.get(
        QMessageBox.StandardButton(answer), "cancel")


def ask_abort(parent: QWidget) -> bool:
    """While marking: True when the operator chooses to abort it (laser off) and quit."""
    box = QMessageBox(QMessageBox.Icon.Warning, "Marking under way",
                      "The laser is marking. Abort the job (laser off, the journal keeps how "
                      "far it got) and quit?", QMessageBox.StandardButton.Cancel, parent)
    abort = box.addButton("Abort and quit", QMessageBox.ButtonRole.DestructiveRole)
    box.setDefaultButton(QMessageBox.StandardButton.Cancel)
    box.exec()
    return box.clickedButton() is abort
