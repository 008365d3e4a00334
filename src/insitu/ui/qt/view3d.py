"""The 3-D view: a QOpenGLWidget showing the cloud (coloured by height), the scan field, the
scan region and the patterns; orbit (left drag), pan (right or middle drag), zoom (wheel),
and, on the selected pattern, move (drag inside it), turn (drag the round handle) and scale
(drag the corner handle); shift + drag draws the scan region on z = 0. It emits what the
operator asked for; the window applies it to the session."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QMouseEvent, QPainter, QPolygonF, QWheelEvent
from PySide6.QtOpenGLWidgets import QOpenGLWidget

from insitu.ui.model import scene_data as sd
from insitu.ui.model.orbit_camera import OrbitCamera
from insitu.ui.qt.gl_renderer import Renderer

HANDLE_PX = 9
SETTLE_MS = 250                 # full detail this long after the view stopped moving


class View3D(QOpenGLWidget):
    """Signals carry world mm; ``drag`` is an object the same for one whole mouse drag (so
    one drag is one undo step)."""

    pattern_moved = Signal(float, float, object)
    rotate_dragged = Signal(float, float, object)               # mouse x, y
    scale_dragged = Signal(float, float, float, float, object)  # drag start x, y; mouse x, y
    region_drawn = Signal(object)           # (x0, x1, y0, y1) mm
    gl_ready = Signal(str)                  # the renderer's name

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("view3d")
        self.setMinimumSize(320, 240)
        self.setMouseTracking(False)
        self.camera = OrbitCamera()
        self.renderer = Renderer()
        self.renderer_name = ""
        self.handles: sd.Handles | None = None
        self.handle_z = 0.0                 # height the selected pattern is drawn and picked at
        self.moving = False             # orbit, pan or zoom under way: draw the thinned cloud
        self._settle = QTimer(self, singleShot=True, interval=SETTLE_MS)
        self._settle.timeout.connect(self._settled)
        self._drag: dict | None = None

    # -- content -------------------------------------------------------------------------
    def set_cloud(self, points: np.ndarray | None, z_range=None) -> None:
        """(N, 3) mm, or None to clear; ``z_range``: colour scale (default: the points')."""
        pts = np.zeros((0, 3)) if points is None else np.asarray(points).reshape(-1, 3)
        self.renderer.points.set(pts)
        if z_range is None and len(pts):
            z = pts[:, 2]
            z_range = (float(np.percentile(z, 0.5)), float(np.percentile(z, 99.5)))
        if z_range is not None:
            self.renderer.z_range = z_range
        self.update()

    def append_points(self, points: np.ndarray) -> None:
        self.renderer.points.append(points)
        self.update()

    def set_lines(self, name: str, vertices: np.ndarray, colour) -> None:
        self.renderer.set_lines(name, vertices, colour)
        self.update()

    def set_view(self, name: str) -> None:
        self.camera.set_view(name)
        self.update()

    def frame_all(self, lo, hi) -> None:
        self.camera.frame(lo, hi)
        self.update()

    # -- GL ------------------------------------------------------------------------------
    def initializeGL(self) -> None:
        self.renderer_name = self.renderer.initialize()
        self.gl_ready.emit(self.renderer_name)

    def paintGL(self) -> None:
        self.renderer.draw(self.camera.mvp(self.width() / max(self.height(), 1)), self.moving)
        if self.handles is not None or self._drag and self._drag["kind"] == "region":
            self._paint_overlay()

    def _paint_overlay(self) -> None:
        p = QPainter(self)
        p.setRenderHint(QPainter.Antialiasing)
        if self.handles is not None:
            rot, scl = self._handle_px()
            p.setPen(QColor(80, 220, 255))
            p.setBrush(QColor(80, 220, 255, 160))
            p.drawEllipse(QPointF(*rot), HANDLE_PX / 2 + 1, HANDLE_PX / 2 + 1)
            p.drawRect(int(scl[0] - HANDLE_PX / 2), int(scl[1] - HANDLE_PX / 2), HANDLE_PX,
                       HANDLE_PX)
        if self._drag and self._drag["kind"] == "region":
            a, b = self._drag["start_px"], self._drag["now_px"]
            p.setPen(QColor(240, 200, 50))
            p.setBrush(QColor(240, 200, 50, 40))
            p.drawRect(int(min(a[0], b[0])), int(min(a[1], b[1])), int(abs(b[0] - a[0])),
                       int(abs(b[1] - a[1])))
        p.end()

    # -- picking -------------------------------------------------------------------------
    def _screen(self, xy, z) -> np.ndarray:
        pts = np.c_[np.atleast_2d(xy), np.full(len(np.atleast_2d(xy)), z)]
        return self.camera.project(pts, self.width(), self.height())

    def _handle_px(self) -> tuple[np.ndarray, np.ndarray]:
        s = self._screen(np.vstack([self.handles.rotate, self.handles.scale]), self.handle_z)
        return s[0], s[1]

    def world_at(self, x_px: float, y_px: float, z: float) -> np.ndarray | None:
        """(x, y) mm on the plane at height ``z`` under the widget pixel, or None."""
        p = self.camera.pick_plane(x_px, y_px, self.width(), self.height(), z)
        return None if p is None else p[:2]

    def _hit(self, x: float, y: float) -> str | None:
        if self.handles is None:
            return None
        rot, scl = self._handle_px()
        if np.hypot(*(rot - (x, y))) <= HANDLE_PX:
            return "rotate"
        if np.hypot(*(scl - (x, y))) <= HANDLE_PX:
            return "scale"
        poly = QPolygonF([QPointF(*c) for c in self._screen(self.handles.corners,
                                                            self.handle_z)])
        return "move" if poly.containsPoint(QPointF(x, y), Qt.OddEvenFill) else None

    # -- mouse ---------------------------------------------------------------------------
    def mousePressEvent(self, e: QMouseEvent) -> None:
        x, y = e.position().x(), e.position().y()
        kind = "orbit"
        if e.button() == Qt.LeftButton and e.modifiers() & Qt.ShiftModifier:
            kind = "region"
        elif e.button() == Qt.LeftButton:
            kind = self._hit(x, y) or "orbit"
        elif e.button() in (Qt.RightButton, Qt.MiddleButton):
            kind = "pan"
        z = 0.0 if kind == "region" else self.handle_z
        self._drag = {"kind": kind, "start_px": (x, y), "now_px": (x, y), "last_px": (x, y),
                      "start_xy": self.world_at(x, y, z), "key": object(),
                      "centre": None if self.handles is None else self.handles.centre.copy()}
        e.accept()

    def mouseMoveEvent(self, e: QMouseEvent) -> None:
        d = self._drag
        if d is None:
            return
        x, y = e.position().x(), e.position().y()
        dx, dy = x - d["last_px"][0], y - d["last_px"][1]
        d["last_px"] = d["now_px"] = (x, y)
        kind = d["kind"]
        if kind == "orbit":
            self.moving = True
            self.camera.orbit(-0.4 * dx, 0.4 * dy)
        elif kind == "pan":
            self.moving = True
            self.camera.pan(dx, dy, max(self.height(), 1))
        elif kind in ("move", "rotate", "scale"):
            xy = self.world_at(x, y, self.handle_z)
            if xy is not None and d["start_xy"] is not None:
                if kind == "move":
                    at = d["centre"] + (xy - d["start_xy"])
                    self.pattern_moved.emit(float(at[0]), float(at[1]), d["key"])
                elif kind == "rotate":
                    self.rotate_dragged.emit(float(xy[0]), float(xy[1]), d["key"])
                else:
                    self.scale_dragged.emit(float(d["start_xy"][0]), float(d["start_xy"][1]),
                                            float(xy[0]), float(xy[1]), d["key"])
        self.update()

    def mouseReleaseEvent(self, e: QMouseEvent) -> None:
        d, self._drag = self._drag, None
        if d is not None and d["kind"] == "region":
            a = d["start_xy"]
            b = self.world_at(e.position().x(), e.position().y(), 0.0)
            if a is not None and b is not None:
                self.region_drawn.emit((float(min(a[0], b[0])), float(max(a[0], b[0])),
                                        float(min(a[1], b[1])), float(max(a[1], b[1]))))
        self._settle.start()
        self.update()

    def wheelEvent(self, e: QWheelEvent) -> None:
        self.moving = True
        self.camera.zoom(0.85 ** (e.angleDelta().y() / 120.0))
        self._settle.start()
        self.update()

    def _settled(self) -> None:
        if self._drag is None:
            self.moving = False
            self.update()
