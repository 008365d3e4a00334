"""The keys of a laser station. Keys go to the 3-D view unless a field is being edited:

- a field (spin box, line edit) keeps what it types; Enter commits it and Esc reverts it to
  the value it holds, and both hand the keys back to the view; Ctrl+Z / Ctrl+Shift+Z in a
  field undo / redo the placement (the window's Undo / Redo), not the field's text — an
  edit not yet committed is dropped; lists, tables and combo boxes keep their arrow keys;
- the view's single keys (1–4, O, F, C, the arrows nudging the selected pattern, Shift ×10)
  are the window's shortcuts, so they work wherever else the focus is;
- the Laser menu: Preview — the red pilot light — F1 and Mark F2 (as in EZCAD), Resume, and
  ABORT on Esc or Space while a job is marking. While marking, Esc aborts wherever the
  focus is (a field's edit is then left as it was typed); otherwise Esc reverts a field.
"""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt, QTimer
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QAbstractItemView, QAbstractSpinBox, QComboBox, QLineEdit, QWidget

NUDGE_MM = 0.1
"""An arrow key moves the selected pattern this far; with Shift ten times as far."""
ARROWS = {Qt.Key.Key_Left: (-1, 0), Qt.Key.Key_Right: (1, 0), Qt.Key.Key_Up: (0, 1),
          Qt.Key.Key_Down: (0, -1)}
COMMIT = (Qt.Key.Key_Return, Qt.Key.Key_Enter)


def _revert(field: QWidget) -> None:
    """Show the value ``field`` holds again (what was typed is dropped)."""
    if isinstance(field, QAbstractSpinBox):
        field.lineEdit().setText(field.prefix() + field.textFromValue(field.value())
                                 + field.suffix())
    elif isinstance(field, QLineEdit):
        field.setText(field.property("committedText") or "")


class _FieldKeys(QObject):
    """An event filter on a window's fields: Undo / Redo to the placement's (the Place
    dock's fields), Enter and Esc back to the view (Esc reverting), arrows kept by the widget
    that uses them, Esc and Space left to ABORT while marking."""

    def __init__(self, window, parent: QObject):
        super().__init__(parent)
        self.window = window
        self.undo = {QKeySequence.StandardKey.Undo: window.undo_action,
                     QKeySequence.StandardKey.Redo: window.redo_action}

    def eventFilter(self, obj, event) -> bool:
        kind = event.type()
        if kind == QEvent.Type.FocusIn and isinstance(obj, QLineEdit):
            obj.setProperty("committedText", obj.text())
        if kind not in (QEvent.Type.ShortcutOverride, QEvent.Type.KeyPress):
            return False
        editable = isinstance(obj, (QAbstractSpinBox, QLineEdit))
        abort = self.window.mark_panel.abort_action
        if abort.isEnabled() and event.key() in (Qt.Key.Key_Escape, Qt.Key.Key_Space):
            event.ignore()                      # marking: the window's ABORT shortcut fires
            return kind == QEvent.Type.ShortcutOverride
        if editable and self.window.place_panel.isAncestorOf(obj):
            for key, action in self.undo.items():
                if event.matches(key):
                    event.accept()
                    if kind == QEvent.Type.KeyPress:
                        action.trigger()
                    return kind == QEvent.Type.KeyPress
        if kind == QEvent.Type.ShortcutOverride:
            if event.key() in ARROWS and event.modifiers() in (Qt.KeyboardModifier.NoModifier,
                                                               Qt.KeyboardModifier.ShiftModifier):
                event.accept()                  # the widget moves in itself
            return False
        if editable and event.key() in COMMIT:
            if isinstance(obj, QLineEdit):
                obj.setProperty("committedText", obj.text())
            QTimer.singleShot(0, self.window.view.setFocus)
        elif editable and event.key() == Qt.Key.Key_Escape:
            _revert(obj)
            self.window.view.setFocus()
            return True
        return False


def route_keys(window, widgets: list[QWidget]) -> None:
    """Install the field keys on the fields, lists and combo boxes in ``widgets``."""
    keys = _FieldKeys(window, window)
    kinds = (QAbstractSpinBox, QLineEdit, QComboBox, QAbstractItemView)
    for w in widgets:
        for field in [c for kind in kinds for c in w.findChildren(kind)]:
            if isinstance(field, QLineEdit) and isinstance(field.parent(), QAbstractSpinBox):
                continue                        # its spin box has the filter
            field.installEventFilter(keys)


def add_nudge_actions(window) -> list[QAction]:
    """Arrow keys (Shift: ×10) nudge the selected pattern; the window's shortcuts."""
    out = []
    for key, (dx, dy) in ARROWS.items():
        name = {(-1, 0): "left", (1, 0): "right", (0, 1): "up", (0, -1): "down"}[(dx, dy)]
        for shift, step in (("", NUDGE_MM), ("Shift+", 10 * NUDGE_MM)):
            a = QAction(f"Nudge the pattern {name} {step:g} mm", window)
            a.setShortcut(QKeySequence(shift + QKeySequence(key).toString()))
            a.triggered.connect(lambda _=False, x=dx * step, y=dy * step: window._nudged(x, y))
            window.addAction(a)
            out.append(a)
    return out


def add_laser_menu(window, menu, toolbar) -> None:
    """The Laser menu: the Mark dock's Preview (F1), Mark (F2), Resume and ABORT (Esc,
    Space) actions, also on the toolbar."""
    panel = window.mark_panel
    for a in (panel.preview_action, panel.mark_action, panel.resume_action):
        menu.addAction(a)
    menu.addSeparator()
    menu.addAction(panel.abort_action)
    toolbar.addSeparator()
    toolbar.addActions([panel.preview_action, panel.mark_action, panel.abort_action])
    window.nudge_actions = add_nudge_actions(window)
    route_keys(window, [window.place_panel, window.scan_panel, window.mark_panel,
                        window.engrave_panel, window.calibrate_panel, window.production_panel])
