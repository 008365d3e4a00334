"""A picture at full size in its own window: the wheel (or + / −) zooms about the cursor,
dragging pans, 0 fits it to the window, 1 shows it pixel for pixel. Used for the calibration
reports (a click on the picture of a Calibrate page)."""

from __future__ import annotations

from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtGui import QPainter, QPixmap
from PySide6.QtWidgets import (QDialog, QGraphicsPixmapItem, QGraphicsScene, QGraphicsView,
                               QLabel, QVBoxLayout, QWidget)

ZOOM_STEP = 1.25


class ZoomView(QGraphicsView):
    """A pixmap in a graphics view with wheel zoom about the cursor and drag to pan."""

    def __init__(self, pixmap: QPixmap, parent: QWidget | None = None):
        super().__init__(parent)
        self.setScene(QGraphicsScene(self))
        self.item = QGraphicsPixmapItem(pixmap)
        self.item.setTransformationMode(Qt.TransformationMode.SmoothTransformation)
        self.scene().addItem(self.item)
        self.setDragMode(QGraphicsView.DragMode.ScrollHandDrag)
        self.setTransformationAnchor(QGraphicsView.ViewportAnchor.AnchorUnderMouse)
        self.setRenderHint(QPainter.RenderHint.SmoothPixmapTransform)

    def zoom(self) -> float:
        """Screen pixels per picture pixel."""
        return self.transform().m11()

    def zoom_by(self, factor: float) -> None:
        self.scale(factor, factor)

    def fit(self) -> None:
        self.fitInView(self.item, Qt.AspectRatioMode.KeepAspectRatio)

    def actual_size(self) -> None:
        self.resetTransform()

    def wheelEvent(self, e) -> None:
        self.zoom_by(ZOOM_STEP if e.angleDelta().y() > 0 else 1 / ZOOM_STEP)

    def _key_action(self, e):
        return {Qt.Key.Key_Plus: lambda: self.zoom_by(ZOOM_STEP),
                Qt.Key.Key_Equal: lambda: self.zoom_by(ZOOM_STEP),
                Qt.Key.Key_Minus: lambda: self.zoom_by(1 / ZOOM_STEP),
                Qt.Key.Key_0: self.fit, Qt.Key.Key_1: self.actual_size}.get(Qt.Key(e.key()))

    def event(self, e) -> bool:
        """The zoom keys are this view's while it has focus (not the main window's view
        keys 1–4)."""
        if e.type() == QEvent.Type.ShortcutOverride and self._key_action(e) is not None:
            e.accept()
            return True
        return super().event(e)

    def keyPressEvent(self, e) -> None:
        action = self._key_action(e)
        if action is None:
            super().keyPressEvent(e)
        else:
            action()


class ImageWindow(QDialog):
    """``pixmap`` titled ``title``, fitted to the window when it opens."""

    def __init__(self, pixmap: QPixmap, title: str, parent: QWidget | None = None):
        super().__init__(parent)
        self.setWindowTitle(title)
        self.view = ZoomView(pixmap, self)
        hint = QLabel(f"{pixmap.width()} × {pixmap.height()} px — wheel or +/− zooms, drag "
                      "pans, 0 fits, 1 is pixel for pixel")
        lay = QVBoxLayout(self)
        lay.addWidget(self.view)
        lay.addWidget(hint)
        self.resize(min(pixmap.width() + 40, 1400), min(pixmap.height() + 70, 1000))

    def showEvent(self, e) -> None:
        super().showEvent(e)
        self.view.fit()


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
