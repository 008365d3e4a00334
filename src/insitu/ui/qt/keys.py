"""Undo and redo while a field has focus: Ctrl+Z / Ctrl+Shift+Z in a spin box or line edit
of a dock undo the placement (the window's Undo / Redo actions), not the field's own text —
the field then shows the placement's value; an edit not yet committed is dropped."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QAbstractSpinBox, QLineEdit, QWidget


class _UndoRouter(QObject):
    """An event filter: a field's Undo / Redo key goes to ``undo`` / ``redo``."""

    def __init__(self, undo: QAction, redo: QAction, parent: QObject):
        super().__init__(parent)
        self.actions = {QKeySequence.StandardKey.Undo: undo, QKeySequence.StandardKey.Redo: redo}

    def eventFilter(self, obj, event) -> bool:
        if event.type() in (QEvent.Type.ShortcutOverride, QEvent.Type.KeyPress):
            for key, action in self.actions.items():
                if event.matches(key):
                    event.accept()
                    if event.type() == QEvent.Type.KeyPress:
                        action.trigger()
                    return event.type() == QEvent.Type.KeyPress
        return False


def route_undo(panel: QWidget, undo: QAction, redo: QAction) -> None:
    """Route Undo / Redo keys from every spin box and line edit of ``panel`` to ``undo`` /
    ``redo``."""
    router = _UndoRouter(undo, redo, panel)
    for field in panel.findChildren(QAbstractSpinBox) + panel.findChildren(QLineEdit):
        field.installEventFilter(router)
