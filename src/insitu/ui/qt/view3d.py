"""The 3-D view: a QOpenGLWidget showing the cloud (coloured by height or by the camera's
ambient gray), the scan field, the scan region and the patterns, over a mm grid on z = 0
with the x/y/z axes, and with rulers, a scale bar and a colour bar painted over it
(:mod:`.view_overlay`). Orthographic top view for placing, perspective for looking: a click
takes the keyboard's focus and selects the pattern under it; on the selected pattern, move
(drag inside it), turn (drag the round handle) and scale (drag the corner handle); a left
drag on empty space draws a selection box in the top view (as in a laser's layout program)
and orbits in the others (Alt + drag orbits the top view); pan (right or middle drag), zoom
(wheel); shift + drag draws the scan region on z = 0. It emits what the operator asked for;
the window applies it to the session."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, Qt, QTimer, Signal
from PySide6.QtGui import QMouseEvent, QPainter, QPolygonF, QWheelEvent
from PySide6.QtOpenGLWidgets import QOpenGLWidget

from insitu.ui.model import scene_data as sd
from insitu.ui.model import view_guides as vg
from insitu.ui.model.orbit_camera import OrbitCamera
from insitu.ui.qt import view_overlay
from insitu.ui.qt.gl_renderer import Renderer
from insitu.ui.qt.view_overlay import AXIS_COLOURS, BAR_BAND_PX, HANDLE_PX, colour_bar_range

SETTLE_MS = 250                 # full detail this long after the view stopped moving
SELECT_MIN_PX = 4               # a shorter drag on empty space is a click, not a box
GRID_COLOUR = (0.5, 0.53, 0.58, 0.22)
GRID_MAJOR_COLOUR = (0.6, 0.63, 0.68, 0.45)


class View3D(QOpenGLWidget):
    """Signals carry world mm; ``drag`` is an object the same for one whole mouse drag (so
    one drag is one undo step)."""

    pattern_moved = Signal(float, float, object)
    rotate_dragged = Signal(float, float, object)               # mouse x, y
    scale_dragged = Signal(float, float, float, float, object)  # drag start x, y; mouse x, y
    region_drawn = Signal(object)           # (x0, x1, y0, y1) mm
    box_selected = Signal(object)           # (x0, x1, y0, y1) mm, on the plane of the handles
    clicked_at = Signal(float, float)       # x, y mm: a press, on the plane of the handles
    gl_ready = Signal(str)                  # the renderer's name
    projection_changed = Signal(bool)       # orthographic?

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setObjectName("view3d")
        self.setMinimumSize(320, 240)
        self.setMouseTracking(False)
        self.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
        self.camera = OrbitCamera()
        self.camera.set_view("top")
        self.renderer = Renderer()
        self.grid: vg.Grid | None = None
        self._axes_mm = 0.0
        self.renderer_name = ""
        self.handles: sd.Handles | None = None
        self.handle_z = 0.0                 # height the selected pattern is drawn and picked at
        self.moving = False             # orbit, pan or zoom under way: draw the thinned cloud
        self._settle = QTimer(self, singleShot=True, interval=SETTLE_MS)
        self._settle.timeout.connect(self._settled)
        self._drag: dict | None = None

    # -- content -------------------------------------------------------------------------
    def set_cloud(self, points: np.ndarray | None, z_range=None,
                  ambient: np.ndarray | None = None) -> None:
        """(N, 3) mm, or None to clear; ``z_range``: colour scale (default: the points');
        ``ambient``: (N,) 0…1 gray of the ambient camera frame at each point, or None."""
        pts = np.zeros((0, 3)) if points is None else np.asarray(points).reshape(-1, 3)
        self.renderer.points.set(pts, ambient)
        if z_range is None and len(pts):
            z_range = (float(pts[:, 2].min()), float(pts[:, 2].max()))
        if z_range is not None:
            self.renderer.z_range = z_range
        if ambient is not None and len(pts):
            lo, hi = np.percentile(np.asarray(ambient, np.float32), (1.0, 99.0))
            self.renderer.ambient_range = (float(lo), float(max(hi, lo + 1e-3)))
        self.update()

    @property
    def has_camera_colours(self) -> bool:
        """Does the cloud carry the ambient gray the camera colours need?"""
        return self.renderer.points.has_ambient

    def set_camera_colours(self, on: bool) -> None:
        """Colour by the camera's ambient gray (True) or by height (a uniform: no upload)."""
        self.renderer.camera_colours = bool(on)
        self.update()

    def set_ortho(self, on: bool) -> None:
        if self.camera.ortho != bool(on):
            self.camera.ortho = bool(on)
            self.projection_changed.emit(self.camera.ortho)
        self.update()

    def append_points(self, points: np.ndarray) -> None:
        self.renderer.points.append(points)
        self.update()

    def set_lines(self, name: str, vertices: np.ndarray, colour) -> None:
        self.renderer.set_lines(name, vertices, colour)
        self.update()

    def set_view(self, name: str) -> None:
        """A preset view: top (orthographic), front, side, iso (perspective)."""
        was = self.camera.ortho
        self.camera.set_view(name)
        if self.camera.ortho != was:
            self.projection_changed.emit(self.camera.ortho)
        self.update()

    def frame_all(self, lo, hi) -> None:
        """Fit the box (lo, hi) mm into the view (its eight corners inside, with a margin),
        left of the colour bar when one is shown."""
        w = max(self.width(), 1)
        reserve = min(BAR_BAND_PX / w, 0.4) if colour_bar_range(self) is not None else 0.0
        self.camera.frame(lo, hi, w / max(self.height(), 1), reserve)
        self.update()

    # -- GL ------------------------------------------------------------------------------
    def initializeGL(self) -> None:
        self.renderer_name = self.renderer.initialize()
        self.gl_ready.emit(self.renderer_name)

    def paintGL(self) -> None:
        self._update_guides()
        dpr = self.devicePixelRatioF()
        self.renderer.draw(self.camera.mvp(self.width() / max(self.height(), 1)), self.moving,
                           int(self.width() * self.height() * dpr * dpr))
        p = QPainter(self)
        view_overlay.paint(self, p)
        p.end()

    def _update_guides(self) -> None:
        """The grid and the axes for the current zoom (uploaded when they changed)."""
        g = vg.grid(self.camera, self.width(), self.height())
        old = self.grid
        if old is None or old.step_mm != g.step_mm or not np.array_equal(old.minor, g.minor) \
                or not np.array_equal(old.major, g.major):
            self.grid = g
            self.renderer.set_lines("grid", g.minor, GRID_COLOUR)
            self.renderer.set_lines("grid_major", g.major, GRID_MAJOR_COLOUR)
        length, axes = vg.axes(self.camera, self.height())
        if length != self._axes_mm:
            self._axes_mm = length
            for i, name in enumerate(("axis_x", "axis_y", "axis_z")):
                self.renderer.set_lines(name, axes[2 * i:2 * i + 2], AXIS_COLOURS[i], True)

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

    def is_top(self) -> bool:
        """The orthographic view straight down (placing)."""
        return self.camera.ortho and self.camera.elevation_deg > 89.0

    # -- mouse ---------------------------------------------------------------------------
    def mousePressEvent(self, e: QMouseEvent) -> None:
        self.setFocus(Qt.FocusReason.MouseFocusReason)
        x, y = e.position().x(), e.position().y()
        kind = "orbit"
        if e.button() == Qt.LeftButton and e.modifiers() & Qt.ShiftModifier:
            kind = "region"
        elif e.button() == Qt.LeftButton:
            kind = self._hit(x, y)
            if kind is None:                # another pattern under the mouse: select it
                xy = self.world_at(x, y, self.handle_z)
                if xy is not None:
                    self.clicked_at.emit(float(xy[0]), float(xy[1]))
                kind = self._hit(x, y) or ("select" if self.is_top() and not
                                           e.modifiers() & Qt.AltModifier else "orbit")
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
        if d is not None and d["kind"] == "select":
            a = d["start_xy"]
            b = self.world_at(e.position().x(), e.position().y(), self.handle_z)
            moved = np.hypot(*(np.subtract(d["start_px"], (e.position().x(),
                                                            e.position().y()))))
            if a is not None and b is not None and moved >= SELECT_MIN_PX:
                self.box_selected.emit((float(min(a[0], b[0])), float(max(a[0], b[0])),
                                        float(min(a[1], b[1])), float(max(a[1], b[1]))))
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
