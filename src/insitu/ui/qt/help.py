"""The Help menu: the operator guide (docs/operator-guide.md, shipped beside the forms),
the keyboard shortcuts of every action (read from the actions themselves) and About (the
versions of insitu, Qt and the OpenGL renderer)."""

from __future__ import annotations

import platform
from pathlib import Path

from PySide6 import __version__ as pyside_version
from PySide6.QtCore import qVersion
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import (
    QDialog,
    QMessageBox,
    QTableWidget,
    QTableWidgetItem,
    QTextBrowser,
    QVBoxLayout,
    QWidget,
)

import insitu
from insitu.ui.qt.forms import ASSETS

GUIDE = "operator-guide.md"


def guide_candidates() -> list[Path]:
    """Where the operator guide is looked for: beside the forms (the package), then the
    repository's docs/ folder."""
    return [ASSETS / GUIDE, ASSETS.resolve().parent / "docs" / GUIDE]


def guide_path() -> Path | None:
    return next((p for p in guide_candidates() if p.is_file()), None)


class GuideWindow(QDialog):
    """The operator guide rendered from Markdown, or a line saying where it was looked for."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.setWindowTitle("insitu — operator guide")
        self.resize(820, 900)
        self.browser = QTextBrowser(self)
        self.browser.setOpenExternalLinks(True)
        QVBoxLayout(self).addWidget(self.browser)
        path = guide_path()
        if path is None:
            looked = ", ".join(str(p) for p in guide_candidates())
            self.browser.setPlainText(f"The operator guide ({GUIDE}) is not installed: looked "
                                      f"for {looked}. It is docs/{GUIDE} in the insitu "
                                      "repository.")
        else:
            self.browser.setSearchPaths([str(path.resolve().parent)])
            self.browser.setMarkdown(path.read_text(encoding="utf-8"))
        self.path = path


def shortcut_rows(window: QWidget) -> list[tuple[str, str]]:
    """(action, its shortcuts) for every action of ``window`` that has one, in the order the
    actions were made, each once."""
    rows, seen = [], set()
    for a in window.findChildren(QAction):
        keys = ", ".join(k.toString(QKeySequence.SequenceFormat.NativeText)
                         for k in a.shortcuts() if not k.isEmpty())
        name = a.text().replace("&&", "\0").replace("&", "").replace("\0", "&").rstrip("…")
        if keys and (name, keys) not in seen:
            seen.add((name, keys))
            rows.append((name, keys))
    return rows


class ShortcutsWindow(QDialog):
    """A table of :func:`shortcut_rows` of ``window``."""

    def __init__(self, window: QWidget):
        super().__init__(window)
        self.setWindowTitle("insitu — keyboard shortcuts")
        rows = shortcut_rows(window)
        self.table = QTableWidget(len(rows), 2, self)
        self.table.setHorizontalHeaderLabels(["Action", "Shortcut"])
        for r, (name, keys) in enumerate(rows):
            self.table.setItem(r, 0, QTableWidgetItem(name))
            self.table.setItem(r, 1, QTableWidgetItem(keys))
        self.table.resizeColumnsToContents()
        self.table.verticalHeader().hide()
        QVBoxLayout(self).addWidget(self.table)
        self.resize(420, 520)


def about_text(window) -> str:
    gl = getattr(window.view, "renderer_name", "") or "not started yet"
    return (f"insitu {insitu.__version__}: in-situ structured-light measurement and laser "
            f"marking with a 3-D galvo scan head.\n\nQt {qVersion()} (PySide6 "
            f"{pyside_version}), Python {platform.python_version()}\nOpenGL: {gl}")


def add_help_menu(window) -> None:
    """The Help menu of ``window`` (a MainWindow); its windows are kept in
    ``window.help_windows``."""
    window.help_windows = {}
    m = window.menuBar().addMenu("&Help")

    def show(name, make):
        w = window.help_windows.get(name)
        if w is None or name == "shortcuts":          # the shortcuts as they are now
            w = window.help_windows[name] = make()
        w.show()
        w.raise_()

    window.guide_action = window._action(m, "Operator &guide", lambda: show(
        "guide", lambda: GuideWindow(window)), "Shift+F1")      # F1: the red light
    window.shortcuts_action = window._action(m, "&Keyboard shortcuts", lambda: show(
        "shortcuts", lambda: ShortcutsWindow(window)))
    window.about_action = window._action(m, "&About insitu", lambda: show(
        "about", lambda: QMessageBox(QMessageBox.Icon.Information, "About insitu",
                                     about_text(window), QMessageBox.StandardButton.Ok,
                                     window)))
