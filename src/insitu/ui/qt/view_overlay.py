"""What the 3-D view paints over its OpenGL picture with a QPainter: the rulers along the
bottom and left edges (x and y mm, in the top view only: in the others a screen distance is
no distance on the part), the scale bar, the colour bar (height colours with the cloud's z
range in mm, or the camera's gray, with ticks), the axis names, and the selected pattern's
outline and handles; the scan region or the selection box while it is drawn."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QColor, QFont, QLinearGradient, QPainter, QPen, QPolygonF

from insitu.ui.model import view_guides as vg
from insitu.ui.model.scene_data import COLORMAP_STOPS

RULER_PX = 22                    # ruler band width
BAR_W, BAR_H = 16, 180           # colour bar, px
BAR_BAND_PX = BAR_W + 12 + 84    # the colour bar's band with its labels, from the right edge
HANDLE_PX = 9
TEXT = QColor(225, 228, 232)
BAND = QColor(48, 52, 60, 235)
AXIS_COLOURS = ((0.95, 0.3, 0.3, 1.0), (0.35, 0.9, 0.35, 1.0), (0.35, 0.55, 1.0, 1.0))


def mm_text(v: float) -> str:
    """A ruler or bar label: no trailing zeros ("12.5", "-40", "0.02")."""
    s = f"{round(float(v), 3) + 0.0:.3f}".rstrip("0").rstrip(".")
    return "0" if s in ("", "-0") else s


def paint(view, p: QPainter) -> None:
    """Everything over the GL picture of ``view`` (a View3D)."""
    p.setRenderHint(QPainter.Antialiasing)
    p.setFont(QFont(p.font().family(), 8))
    w, h = view.width(), view.height()
    _axis_names(view, p)
    _outline_and_handles(view, p)
    _region(view, p)
    if view.is_top():
        _rulers(view, p, w, h)
    _scale_bar(view, p, w, h)
    _colour_bar(view, p, w)


def _axis_names(view, p: QPainter) -> None:
    length, _ = vg.axes(view.camera, view.height())
    tips = view.camera.project(np.eye(3) * length * 1.12, view.width(), view.height())
    for (x, y), name, c in zip(tips, "xyz", AXIS_COLOURS):
        if np.isfinite([x, y]).all():
            p.setPen(QColor.fromRgbF(*c))
            p.drawText(QPointF(x - 3, y + 4), name)


def _outline_and_handles(view, p: QPainter) -> None:
    if view.handles is None:
        return
    outline = view._screen(view.handles.corners, view.handle_z)
    if not np.isfinite(outline).all():
        return
    p.setPen(QPen(QColor(80, 220, 255, 200), 1, Qt.DashLine))
    p.setBrush(Qt.NoBrush)
    p.drawPolygon(QPolygonF([QPointF(*c) for c in outline]))
    rot, scl = view._handle_px()
    p.setPen(QColor(80, 220, 255))
    p.setBrush(QColor(80, 220, 255, 160))
    p.drawLine(QPointF(*outline[2:4].mean(0)), QPointF(*rot))
    p.drawEllipse(QPointF(*rot), HANDLE_PX / 2 + 1, HANDLE_PX / 2 + 1)
    p.drawRect(QRectF(scl[0] - HANDLE_PX / 2, scl[1] - HANDLE_PX / 2, HANDLE_PX, HANDLE_PX))


def _region(view, p: QPainter) -> None:
    """The scan region (yellow) or the selection box (cyan, dashed) while it is drawn."""
    d = view._drag
    if not d or d["kind"] not in ("region", "select"):
        return
    a, b = d["start_px"], d["now_px"]
    if d["kind"] == "select":
        p.setPen(QPen(QColor(80, 220, 255), 1, Qt.DashLine))
        p.setBrush(QColor(80, 220, 255, 30))
    else:
        p.setPen(QColor(240, 200, 50))
        p.setBrush(QColor(240, 200, 50, 40))
    p.drawRect(QRectF(min(a[0], b[0]), min(a[1], b[1]), abs(b[0] - a[0]), abs(b[1] - a[1])))


def _rulers(view, p: QPainter, w: int, h: int) -> None:
    p.setPen(Qt.NoPen)
    p.setBrush(BAND)
    p.drawRect(QRectF(0, h - RULER_PX, w, RULER_PX))
    p.drawRect(QRectF(0, 0, RULER_PX, h - RULER_PX))
    for r in vg.rulers(view.camera, w, h):
        p.setPen(QPen(TEXT, 1))
        for pos, v in zip(r.positions_px, r.values_mm):
            label = f"{mm_text(v)}"
            if r.edge == "bottom":
                if pos < RULER_PX:
                    continue
                p.drawLine(QPointF(pos, h - RULER_PX), QPointF(pos, h - RULER_PX + 6))
                p.drawText(QPointF(pos + 3, h - 6), label)
            else:
                if pos > h - RULER_PX:
                    continue
                p.drawLine(QPointF(RULER_PX - 6, pos), QPointF(RULER_PX, pos))
                p.save()
                p.translate(RULER_PX - 8, pos - 3)
                p.rotate(-90)
                p.drawText(QPointF(0, 0), label)
                p.restore()
        p.setPen(QColor(150, 155, 160))
        unit = f"{'xy'[r.axis]} mm"
        if r.edge == "bottom":
            p.drawText(QPointF(w - 40, h - RULER_PX - 4), unit)
        else:
            p.drawText(QPointF(RULER_PX + 4, 14), unit)


def _scale_bar(view, p: QPainter, w: int, h: int) -> None:
    mm, px = vg.scale_bar(view.camera, h)
    x1, y = w - BAR_W - 70, h - RULER_PX - 14
    x0 = x1 - px
    p.setPen(QPen(TEXT, 2))
    p.drawLine(QPointF(x0, y), QPointF(x1, y))
    for x in (x0, x1):
        p.drawLine(QPointF(x, y - 4), QPointF(x, y + 4))
    approx = "" if view.camera.ortho else "≈ "
    p.drawText(QRectF(x0, y - 20, px, 16), Qt.AlignCenter, f"{approx}{mm_text(mm)} mm")


def colour_bar_range(view) -> tuple[str, float, float] | None:
    """("height", z min mm, z max mm) or ("camera", gray lo, hi) the bar shows, or None
    without a cloud."""
    r = view.renderer
    if r.points.positions.count == 0:
        return None
    if r.camera_colours and r.points.has_ambient:
        return ("camera", *r.ambient_range)
    return ("height", *r.z_range)


def bar_ticks(lo: float, hi: float, top_px: float, bottom_px: float, most: int = 6
              ) -> list[tuple[float, float]]:
    """(value, y px) of the colour bar's ticks: round steps (1, 2 or 5 × 10ⁿ) between ``lo``
    (at ``bottom_px``) and ``hi`` (at ``top_px``), at most ``most``, the ends included."""
    span = hi - lo
    if not np.isfinite(span) or span <= 0:
        return [(lo, bottom_px)]
    raw = span / max(most - 1, 1)
    step = min(m * 10.0 ** np.floor(np.log10(raw)) for m in (1, 2, 5, 10)
               if m * 10.0 ** np.floor(np.log10(raw)) >= raw)
    inner = np.arange(np.ceil(lo / step) * step, hi, step)
    inner = inner[(inner - lo > 0.4 * step) & (hi - inner > 0.4 * step)]
    values = [lo, *inner.tolist(), hi]
    return [(v, bottom_px + (v - lo) / span * (top_px - bottom_px)) for v in values]


def _colour_bar(view, p: QPainter, w: int) -> None:
    shown = colour_bar_range(view)
    if shown is None:
        return
    kind, lo, hi = shown
    rect = QRectF(w - BAR_W - 12, 30, BAR_W, BAR_H)
    p.setPen(Qt.NoPen)
    p.setBrush(BAND)
    p.drawRoundedRect(rect.adjusted(-(BAR_BAND_PX - BAR_W - 18), -26, 6, 14), 4, 4)
    g = QLinearGradient(rect.bottomLeft(), rect.topLeft())
    if kind == "height":
        for t, r, gg, b in COLORMAP_STOPS:
            g.setColorAt(float(t), QColor.fromRgbF(float(r), float(gg), float(b)))
    else:
        g.setColorAt(0.0, QColor(0, 0, 0))
        g.setColorAt(1.0, QColor(255, 255, 255))
    p.setPen(QPen(TEXT, 1))
    p.setBrush(g)
    p.drawRect(rect)
    right = Qt.AlignRight | Qt.AlignVCenter
    unit = " mm" if kind == "height" else ""
    for v, y in bar_ticks(lo, hi, rect.top(), rect.bottom()):
        p.drawLine(QPointF(rect.left() - 4, y), QPointF(rect.left(), y))
        p.drawText(QRectF(rect.left() - 80, y - 8, 74, 16), right, mm_text(v) + unit)
    p.drawText(QRectF(rect.left() - 80, rect.top() - 26, 80 + BAR_W, 16), right,
               "height z" if kind == "height" else "camera gray")
