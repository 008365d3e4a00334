"""A picture at full size in its own window (an :class:`~insitu.ui.qt.image_view.ImageView`:
the wheel or + / − zooms, dragging pans, 0 fits it to the window, 1 shows it pixel for
pixel; Esc or Close closes it). Used for the calibration reports (a click on the picture of a
Calibrate page)."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtGui import QPixmap
from PySide6.QtWidgets import QDialog, QDialogButtonBox, QLabel, QVBoxLayout, QWidget

from insitu.ui.qt.image_view import ImageView


class ImageWindow(QDialog):
    """``pixmap`` titled ``title``, fitted to the window when it opens."""

    def __init__(self, pixmap: QPixmap, title: str, parent: QWidget | None = None):
        super().__init__(parent)
        self.setWindowTitle(title)
        self.view = ImageView(self)
        self.view.show_qimage(pixmap.toImage(), None, title)
        hint = QLabel(f"{pixmap.width()} × {pixmap.height()} px — wheel or +/− zooms, drag "
                      "pans, 0 fits, 1 is pixel for pixel")
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close, self)
        self.buttons.rejected.connect(self.reject)
        lay = QVBoxLayout(self)
        lay.addWidget(self.view)
        lay.addWidget(hint)
        lay.addWidget(self.buttons)
        self.resize(min(pixmap.width() + 40, 1400), min(pixmap.height() + 70, 1000))


class Clicks(QObject):
    """An event filter: ``clicked`` when the left button is released over the watched
    widget."""

    clicked = Signal()

    def eventFilter(self, obj, event) -> bool:
        if (event.type() == QEvent.Type.MouseButtonRelease
                and event.button() == Qt.MouseButton.LeftButton):
            self.clicked.emit()
            return True
        return False
