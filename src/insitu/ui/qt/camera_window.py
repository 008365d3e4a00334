"""The camera's picture enlarged: the dock's camera image (with a button to enlarge it), and
a resizable window of its own that follows the dock's image (line frames with their line
centres, inspection images), with zoom (wheel, about the cursor), pan (drag), 1:1 and Fit."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QHBoxLayout, QPushButton, QVBoxLayout, QWidget

from insitu.ui.qt.image_view import ImageView


class CameraWindow(QWidget):
    """A top-level window showing what ``source`` (the dock's ImageView) shows."""

    def __init__(self, source: ImageView, parent=None):
        super().__init__(parent, Qt.Window)
        self.setObjectName("cameraWindow")
        self.setWindowTitle("insitu — camera")
        self.resize(1100, 900)
        self.source = source
        self.image = ImageView(self)
        self.image.setObjectName("cameraWindowImage")
        self.fit_button = QPushButton("Fit")
        self.one_button = QPushButton("1:1")
        self.fit_button.clicked.connect(self.image.fit)
        self.one_button.clicked.connect(self.image.one_to_one)
        buttons = QHBoxLayout()
        buttons.addWidget(self.fit_button)
        buttons.addWidget(self.one_button)
        buttons.addStretch(1)
        layout = QVBoxLayout(self)
        layout.addLayout(buttons)
        layout.addWidget(self.image, 1)
        source.image_changed.connect(self.follow)
        self.follow()

    def follow(self) -> None:
        s = self.source
        if s.image is not None:
            self.image.show_qimage(s.image, s.centres, s.caption)


class CameraDock(QWidget):
    """The Camera dock's content: ``image`` and an Enlarge button (or double-click)."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self.image = ImageView(self)
        self.image.setObjectName("cameraImage")
        self.image.setMinimumSize(320, 240)
        self.window_: CameraWindow | None = None
        self.enlarge_button = QPushButton("Enlarge")
        self.enlarge_button.setToolTip("the camera's picture in a window of its own, to zoom "
                                       "and pan (or double-click the picture)")
        self.enlarge_button.clicked.connect(self.enlarge)
        self.image.enlarge_requested.connect(self.enlarge)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.image, 1)
        row = QHBoxLayout()
        row.addStretch(1)
        row.addWidget(self.enlarge_button)
        layout.addLayout(row)

    def enlarge(self) -> CameraWindow:
        """Show (or raise) the camera window."""
        if self.window_ is None:
            self.window_ = CameraWindow(self.image, self)
        self.window_.show()
        self.window_.raise_()
        return self.window_
