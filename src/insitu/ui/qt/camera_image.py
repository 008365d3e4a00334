"""The camera dock: the latest camera image with the extracted line centres drawn over it
(a live scan), or the inspection image of a marked part."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QColor, QImage, QPainter, QPen
from PySide6.QtWidgets import QWidget


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


class CameraImage(QWidget):
    """Shows ``image`` scaled to fit, and ``centres`` (M, 2) px (u, v) as red dots."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("cameraImage")
        self.setMinimumSize(240, 180)
        self.image: QImage | None = None
        self.centres = np.zeros((0, 2))
        self.caption = "no image"

    def show_image(self, image: np.ndarray, centres: np.ndarray | None = None,
                   caption: str = "") -> None:
        self.image = to_qimage(image)
        self.centres = np.zeros((0, 2)) if centres is None else np.asarray(centres)
        self.caption = caption
        self.update()

    def paintEvent(self, _event) -> None:
        p = QPainter(self)
        p.fillRect(self.rect(), QColor(20, 22, 26))
        if self.image is None:
            p.setPen(QColor(150, 150, 150))
            p.drawText(self.rect(), Qt.AlignCenter, self.caption)
            return
        w, h = self.image.width(), self.image.height()
        s = min(self.width() / w, self.height() / h)
        ox, oy = (self.width() - s * w) / 2, (self.height() - s * h) / 2
        p.drawImage(QRectF(ox, oy, s * w, s * h), self.image)
        if len(self.centres):
            p.setPen(QPen(QColor(255, 60, 60), 2))
            step = max(len(self.centres) // 400, 1)
            for u, v in self.centres[::step]:
                p.drawPoint(QPointF(ox + s * (u + 0.5), oy + s * (v + 0.5)))
        p.setPen(QColor(230, 230, 230))
        p.drawText(8, 16, self.caption)
        p.end()
