"""SVG files (svgelements) → :class:`Pattern` in mm, y up, painted as the file says.

Each shape is painted in document order, its fill first (``fill-rule`` nonzero or evenodd),
then its stroke: a dark paint adds to the marked region, a light one erases what was painted
before it. A stroke at least ``beam_mm`` wide is painted as its area (the centre line buffered
by half the width with the file's ``stroke-linecap``, ``stroke-linejoin`` and
``stroke-miterlimit``; ``vector-effect: non-scaling-stroke`` keeps the width the file gives,
in CSS px); a thinner dark stroke is marked as a line along its centre.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns.model import Pattern, contours_of, region, stroke_region
from insitu.patterns.vector import (BEAM_MM, MM_PER_PX, TOL_MM, Budget, _arc_steps, _check_file,
                                    _fail, _non_empty, bezier_points, bezier_steps, check_extent,
                                    check_finite)

# svgelements turns mm and cm into px with 0.0393701 in/mm; this ppi makes those exact
# (px, pt and pc do not depend on it; inches are then off by 5e-7)
_SVG_PPI = 96.0 / (25.4 * 0.0393701)


def _svg_subpaths(shape, se, tol_px: float, budget: Budget,
                  what: str) -> list[tuple[np.ndarray, bool]]:
    """Flatten one svgelements shape (transforms applied) into (points px, closed) subpaths;
    a lone move-to is a one-point subpath (a dot under a round cap). Every segment's points
    must be finite, and its chords are taken from ``budget``, before it is flattened."""
    path = se.Path(shape)
    path.reify()
    out: list[tuple[np.ndarray, bool]] = []
    pts: list = []
    closed = False

    def flush():
        if pts:
            out.append((np.array(pts, np.float64), closed))

    for seg in path:
        if isinstance(seg, se.Move):
            flush()
            pts, closed = [(seg.end.x, seg.end.y)], False
            continue
        if seg.start is None or seg.end is None:
            continue
        if not pts:
            pts = [(seg.start.x, seg.start.y)]
        ctrl = [(p.x, p.y) for p in (seg.start, getattr(seg, "control", None),
                                     getattr(seg, "control1", None),
                                     getattr(seg, "control2", None), seg.end) if p is not None]
        check_finite(ctrl, budget.path, what)
        if isinstance(seg, se.Arc):
            check_finite([(seg.rx, seg.ry), (seg.sweep, 0.0)], budget.path, what)
        if isinstance(seg, (se.QuadraticBezier, se.CubicBezier)):
            budget.take(bezier_steps(ctrl, tol_px), what)
        elif isinstance(seg, se.Arc):
            budget.take(_arc_steps(max(abs(seg.rx), abs(seg.ry)), seg.sweep, tol_px), what)
        else:
            budget.take(1, what)
        if isinstance(seg, se.Close):
            pts.append((seg.end.x, seg.end.y))
            closed = True
            flush()
            pts, closed = [], False
        elif isinstance(seg, se.Line):
            pts.append((seg.end.x, seg.end.y))
        elif isinstance(seg, se.QuadraticBezier):
            ctrl = [(p.x, p.y) for p in (seg.start, seg.control, seg.end)]
            pts.extend(map(tuple, bezier_points(ctrl, tol_px)[1:]))
        elif isinstance(seg, se.CubicBezier):
            ctrl = [(p.x, p.y) for p in (seg.start, seg.control1, seg.control2, seg.end)]
            pts.extend(map(tuple, bezier_points(ctrl, tol_px)[1:]))
        elif isinstance(seg, se.Arc):
            n = _arc_steps(max(abs(seg.rx), abs(seg.ry)), seg.sweep, tol_px)
            pts.extend(map(tuple, np.asarray(seg.npoint(np.linspace(0, 1, n + 1)))[1:, :2]))
        else:
            pts.append((seg.end.x, seg.end.y))
    flush()
    return out


def _painted(color) -> bool:
    return color is not None and color.value is not None and color.alpha != 0


def _dark(color) -> bool:
    """True for a painted colour that marks (luminance ≤ 0.5); False for none/light/transparent."""
    if not _painted(color):
        return False
    return (0.299 * color.red + 0.587 * color.green + 0.114 * color.blue) / 255.0 <= 0.5


def _stroke_px(el, se) -> float:
    """The stroke's width in px of the document (0: none)."""
    if not _painted(el.stroke):
        return 0.0
    if el.values.get("vector-effect") == "non-scaling-stroke":
        raw = el.values.get("stroke-width", "1")
        return float(se.Length(raw).value(ppi=_SVG_PPI)) if raw else 1.0
    w = el.stroke_width
    return float(w) if w is not None and math.isfinite(float(w)) else 0.0


def _units_note(svg) -> str:
    w, vb = svg.values.get("width"), getattr(svg, "viewbox", None)
    if vb is not None and isinstance(svg.width, (int, float)) and vb.width:
        unit = float(svg.width) * MM_PER_PX / float(vb.width)
        return (f"units: width {w or '100%'}, viewBox {vb.width:g} wide → 1 user unit = "
                f"{unit:.6g} mm")
    if w:
        return f"units: width {w}, no viewBox → 1 user unit = 1 px = {MM_PER_PX:.6g} mm"
    return f"units: no width/height → 1 user unit = 1 px (1/96 in) = {MM_PER_PX:.6g} mm"


def load_svg(path: str | Path, tol_mm: float = TOL_MM, beam_mm: float = BEAM_MM) -> Pattern:
    """SVG file → Pattern (mm, y up, origin at the document's bottom-left corner): fills and
    strokes at least ``beam_mm`` wide become the contours of the painted region, thinner dark
    strokes become paths (see the module docstring). Units come from the document's
    width/height/viewBox (user unit = 1/96 in when there are none); the choice is in
    ``notes``. Text and embedded images are ignored (convert text to paths first)."""
    import svgelements as se

    path = Path(path)
    _check_file(path)
    try:
        svg = se.SVG.parse(str(path), reify=True, ppi=_SVG_PPI)
        height_px = float(svg.height) if isinstance(getattr(svg, "height", None),
                                                    (int, float)) else 0.0
        if not math.isfinite(height_px):
            height_px = 0.0
        tol_px = tol_mm / MM_PER_PX
        filled, dark = shapely.Polygon(), []
        thin: list[np.ndarray] = []
        widths: set[float] = set()
        n_stroke_areas = 0
        budget = Budget(path)

        def paint(g, is_dark: bool):
            nonlocal filled, dark
            if is_dark:
                dark.append(g)
            else:  # a light paint erases what was painted before it
                filled = shapely.unary_union([filled, *dark]).difference(g)
                dark = []

        for el in svg.elements():
            if not isinstance(el, se.Shape) or el.values.get("visibility") in ("hidden",
                                                                               "collapse"):
                continue
            tag = el.values.get("tag", "shape")
            subs = _svg_subpaths(el, se, tol_px, budget, f"a <{tag}>")
            if not subs:
                continue
            check_extent(np.concatenate([q for q, _ in subs]) * MM_PER_PX, path, f"a <{tag}>")
            if _painted(el.fill):
                rule = "evenodd" if el.values.get("fill-rule") == "evenodd" else "nonzero"
                rings = [p[:-1] if c else p for p, c in subs if len(p) >= 3]
                if rings:
                    paint(region(rings, rule), _dark(el.fill))
            w_px = _stroke_px(el, se)
            if w_px <= 0:
                continue
            w_mm = w_px * MM_PER_PX
            widths.add(round(w_mm, 9))
            if w_mm >= beam_mm:
                cap = el.values.get("stroke-linecap", "butt")
                join = el.values.get("stroke-linejoin", "miter")
                limit = float(el.values.get("stroke-miterlimit", 4) or 4)
                g = shapely.unary_union([stroke_region(p[:-1] if c else p, w_px, cap, join,
                                                       limit, c and len(p) >= 4)
                                         for p, c in subs])
                paint(g, _dark(el.stroke))
                n_stroke_areas += 1
            elif _dark(el.stroke):
                thin.extend(p for p, _ in subs if len(p) >= 2)
        filled = shapely.unary_union([filled, *dark])
        # slivers thinner than the tolerance (a fill of a straight path, an erasure's seam)
        parts = shapely.get_parts(filled)
        filled = shapely.unary_union(parts[shapely.area(parts) > 0.5 * tol_px
                                           * shapely.length(parts)])
        notes = [_units_note(svg)]
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 — any parser failure is a bad file, said in one line
        raise _fail(path, "SVG", e) from e

    def to_mm(p: np.ndarray) -> np.ndarray:
        return np.column_stack([p[:, 0] * MM_PER_PX, (height_px - p[:, 1]) * MM_PER_PX])

    if n_stroke_areas:
        notes.append(f"{n_stroke_areas} stroke(s) ≥ beam {beam_mm:g} mm marked as areas")
    if thin:
        notes.append(f"{len(thin)} stroke line(s) thinner than the beam {beam_mm:g} mm marked "
                     "as lines")
    contours = tuple(to_mm(c) for c in contours_of(filled))
    return _non_empty(Pattern(contours, tuple(to_mm(p) for p in thin), path.name,
                              notes=tuple(notes), stroke_widths=tuple(sorted(widths)),
                              beam_mm=beam_mm),
                      path, "filled or stroked shapes")
