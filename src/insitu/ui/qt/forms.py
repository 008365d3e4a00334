"""The files of the top-level ``ui/`` folder (shipped as ``insitu/ui/assets``): Designer forms,
icons and the stylesheet."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import QFile, QIODevice
from PySide6.QtGui import QIcon
from PySide6.QtUiTools import QUiLoader
from PySide6.QtWidgets import QWidget

ASSETS = Path(__file__).resolve().parents[1] / "assets"


def load_form(name: str, parent: QWidget | None = None) -> QWidget:
    """The widget of Designer form ``name`` (``scan`` → ``scan.ui``)."""
    path = ASSETS / f"{name}.ui"
    f = QFile(str(path))
    if not f.open(QIODevice.ReadOnly):
        raise FileNotFoundError(f"{path}: cannot open the form")
    try:
        widget = QUiLoader().load(f, parent)
    finally:
        f.close()
    if widget is None:
        raise RuntimeError(f"{path}: not a valid Designer form")
    return widget


def icon(name: str) -> QIcon:
    return QIcon(str(ASSETS / "icons" / f"{name}.svg"))


def stylesheet() -> str:
    return (ASSETS / "style.qss").read_text(encoding="utf-8")
