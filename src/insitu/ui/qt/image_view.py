"""One zoomable picture widget for every image the station shows: the camera's latest frame
with the extracted line centres over it (a live scan), the inspection image of a marked part,
a calibration report. Fitted to the widget until the operator zooms (wheel or + / −, about
the cursor) or pans (drag); 0 or :meth:`ImageView.fit` fits it again, 1 or
:meth:`ImageView.one_to_one` shows it pixel for pixel. Double-click asks for an enlarged
window."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QEvent, QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QImage, QPainter, QPen
from PySide6.QtWidgets import QWidget

MAX_CENTRES_DRAWN = 4000
ZOOM_STEP = 1.25                 # per wheel notch
ZOOM_RANGE = (0.02, 64.0)        # screen px per image px


def to_qimage(image: np.ndarray) -> QImage:
    """(H, W) uint8/uint16 grey or (H, W, 3) uint8 BGR → a QImage (a copy)."""
    a = np.asarray(image)
    if a.dtype == np.uint16:
        a = (a >> 8).astype(np.uint8)
    a = np.ascontiguousarray(a.astype(np.uint8, copy=False))
    if a.ndim == 2:
        return QImage(a.data, a.shape[1], a.shape[0], a.strides[0],
                      QImage.Format_Grayscale8).copy()
    rgb = np.ascontiguousarray(a[:, :, 2::-1])
    return QImage(rgb.data, rgb.shape[1], rgb.shape[0], rgb.strides[0],
                  QImage.Format_RGB888).copy()


class ImageView(QWidget):
    """Shows ``image`` and ``centres`` (M, 2) px (u, v) as red dots. The view maps image
    pixel centre (u, v) to widget ``offset + scale · (u + ½, v + ½)``; ``fitted``: the scale
    follows the widget's size."""

    image_changed = Signal()
    enlarge_requested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setMinimumSize(240, 180)
        self.setFocusPolicy(Qt.FocusPolicy.ClickFocus)
        self.image: QImage | None = None
        self.centres = np.zeros((0, 2))
        self.caption = "no image"
        self.fitted = True
        self.scale = 1.0
        self.offset = np.zeros(2)
        self._pan_from: tuple[np.ndarray, np.ndarray] | None = None

    def show_image(self, image: np.ndarray, centres: np.ndarray | None = None,
                   caption: str = "") -> None:
        self.show_qimage(to_qimage(image), centres, caption)

    def show_qimage(self, image: QImage, centres: np.ndarray | None, caption: str) -> None:
        size_changed = self.image is None or self.image.size() != image.size()
        self.image = image
        self.centres = np.zeros((0, 2)) if centres is None else np.asarray(centres)
        self.caption = caption
        if size_changed:
            self.fitted = True
        self.update()
        self.image_changed.emit()

    # -- the view's mapping ----------------------------------------------------------------
    def _fit_now(self) -> None:
        if self.fitted and self.image is not None:
            w, h = self.image.width(), self.image.height()
            self.scale = min(self.width() / w, self.height() / h)
            self.offset = np.array([(self.width() - self.scale * w) / 2,
                                    (self.height() - self.scale * h) / 2])

    def to_widget(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) image px (u, v) → (N, 2) widget px."""
        self._fit_now()
        return self.offset + self.scale * (np.asarray(uv, float) + 0.5)

    def to_image(self, xy) -> np.ndarray:
        """Widget px → image px (u, v)."""
        self._fit_now()
        return (np.asarray(xy, float) - self.offset) / self.scale - 0.5

    def zoom_at(self, factor: float, xy) -> None:
        """Zoom by ``factor`` keeping the image point under widget px ``xy`` where it is."""
        self._fit_now()
        self.zoom_to(self.scale * factor, xy)

    def zoom_to(self, scale: float, xy) -> None:
        """Show ``scale`` screen px per image px, the image point under ``xy`` kept there."""
        uv = self.to_image(xy)
        self.scale = float(np.clip(scale, *ZOOM_RANGE))
        self.offset = np.asarray(xy, float) - self.scale * (uv + 0.5)
        self.fitted = False
        self.update()

    def one_to_one(self) -> None:
        """One image pixel per screen pixel, about the widget's centre."""
        self.zoom_to(1.0, np.array([self.width(), self.height()]) / 2)

    def fit(self) -> None:
        """The whole image in the widget, following its size."""
        self.fitted = True
        self._fit_now()
        self.update()

    # -- events ----------------------------------------------------------------------------
    def wheelEvent(self, e) -> None:
        if self.image is not None:
            self.zoom_at(ZOOM_STEP ** (e.angleDelta().y() / 120.0),
                         (e.position().x(), e.position().y()))
        e.accept()

    def _key_action(self, e):
        centre = np.array([self.width(), self.height()]) / 2
        return {Qt.Key.Key_Plus: lambda: self.zoom_at(ZOOM_STEP, centre),
                Qt.Key.Key_Equal: lambda: self.zoom_at(ZOOM_STEP, centre),
                Qt.Key.Key_Minus: lambda: self.zoom_at(1 / ZOOM_STEP, centre),
                Qt.Key.Key_0: self.fit, Qt.Key.Key_1: self.one_to_one}.get(Qt.Key(e.key()))

    def event(self, e) -> bool:
        """The zoom keys are this view's while it has focus (not the main window's view
        keys 1–4)."""
        if (e.type() == QEvent.Type.ShortcutOverride and self.image is not None
                and self._key_action(e) is not None):
            e.accept()
            return True
        return super().event(e)

    def keyPressEvent(self, e) -> None:
        action = self._key_action(e) if self.image is not None else None
        if action is None:
            super().keyPressEvent(e)
        else:
            action()

    def mousePressEvent(self, e) -> None:
        self._fit_now()
        self._pan_from = (np.array([e.position().x(), e.position().y()]), self.offset.copy())

    def mouseMoveEvent(self, e) -> None:
        if self._pan_from is not None and self.image is not None:
            start, offset = self._pan_from
            self.offset = offset + np.array([e.position().x(), e.position().y()]) - start
            self.fitted = False
            self.update()

    def mouseReleaseEvent(self, _e) -> None:
        self._pan_from = None

    def mouseDoubleClickEvent(self, _e) -> None:
        self.enlarge_requested.emit()

    def paintEvent(self, _event) -> None:
        p = QPainter(self)
        p.fillRect(self.rect(), QColor(20, 22, 26))
        if self.image is None:
            p.setPen(QColor(150, 150, 150))
            p.drawText(self.rect(), Qt.AlignCenter, self.caption)
            return
        self._fit_now()
        w, h = self.image.width(), self.image.height()
        p.setRenderHint(QPainter.SmoothPixmapTransform, self.scale < 1)
        p.drawImage(QRectF(*self.offset, self.scale * w, self.scale * h), self.image)
        if len(self.centres):
            xy = self.to_widget(self.centres)
            inside = (xy[:, 0] >= 0) & (xy[:, 0] < self.width()) & (xy[:, 1] >= 0) & \
                (xy[:, 1] < self.height())
            xy = xy[inside]
            xy = xy[::max(len(xy) // MAX_CENTRES_DRAWN, 1)]
            p.setPen(QPen(QColor(255, 40, 40), max(2.0, min(self.scale * 0.8, 6.0))))
            p.drawPoints([QPointF(x, y) for x, y in xy])
        p.setPen(QColor(230, 230, 230))
        zoom = "fit" if self.fitted else f"{self.scale * 100:.0f} %"
        p.drawText(8, 16, f"{self.caption}   {w}×{h} px, {zoom}")
        p.end()
