"""SVG files (svgelements) → :class:`Pattern` in mm, y up, painted as the file says.

Each shape is painted in document order, its fill first (``fill-rule`` nonzero or evenodd),
then its stroke: a dark paint adds to the marked region, a light one erases what was painted
before it. A stroke at least ``beam_mm`` wide is painted as its area: the centre line buffered
by half the width with the file's ``stroke-linecap``, ``stroke-linejoin`` and
``stroke-miterlimit`` in the element's own user space, then carried by its transform (a
stroke under ``scale(2, 0.5)`` is wide where it runs vertically, narrow where horizontally);
``vector-effect: non-scaling-stroke`` keeps the width the file gives, in CSS px of the page.
A thinner dark stroke is marked as a line along its centre. What lies outside the page
(``width`` × ``height``, or the ``viewBox``) is clipped as a renderer clips it, with a warning.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import shapely
import shapely.affinity

from insitu.errors import FormatError
from insitu.patterns.model import Pattern, contours_of, region, stroke_region
from insitu.patterns.vector import (BEAM_MM, MM_PER_PX, TOL_MM, Budget, _arc_steps, _check_file,
                                    _fail, _non_empty, bezier_points, bezier_steps, check_extent,
                                    check_finite)

# svgelements turns mm and cm into px with 0.0393701 in/mm; this ppi makes those exact
# (px, pt and pc do not depend on it; inches are then off by 5e-7)
_SVG_PPI = 96.0 / (25.4 * 0.0393701)


def _svg_subpaths(shape, se, tol: float, budget: Budget,
                  what: str) -> list[tuple[np.ndarray, bool]]:
    """Flatten one svgelements shape, in its own user space (its transform not applied), into
    (points, closed) subpaths within ``tol`` of the curves; a lone move-to is a one-point
    subpath (a dot under a round cap). Every segment's points must be finite, and its chords
    are taken from ``budget``, before it is flattened."""
    out: list[tuple[np.ndarray, bool]] = []
    pts: list = []
    closed = False

    def flush():
        if pts:
            out.append((np.array(pts, np.float64), closed))

    for seg in shape.segments(transformed=False):
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
            budget.take(bezier_steps(ctrl, tol), what)
        elif isinstance(seg, se.Arc):
            budget.take(_arc_steps(max(abs(seg.rx), abs(seg.ry)), seg.sweep, tol), what)
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
            pts.extend(map(tuple, bezier_points(ctrl, tol)[1:]))
        elif isinstance(seg, se.CubicBezier):
            ctrl = [(p.x, p.y) for p in (seg.start, seg.control1, seg.control2, seg.end)]
            pts.extend(map(tuple, bezier_points(ctrl, tol)[1:]))
        elif isinstance(seg, se.Arc):
            n = _arc_steps(max(abs(seg.rx), abs(seg.ry)), seg.sweep, tol)
            pts.extend(map(tuple, np.asarray(seg.npoint(np.linspace(0, 1, n + 1)))[1:, :2]))
        else:
            pts.append((seg.end.x, seg.end.y))
    flush()
    return out


def _matrix(m) -> np.ndarray:
    """svgelements Matrix → (2, 3) float64 [[a, c, e], [b, d, f]] (user space → page px)."""
    return np.array([[m.a, m.c, m.e], [m.b, m.d, m.f]], np.float64)


def _apply(m: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return pts @ m[:, :2].T + m[:, 2]


def _painted(color) -> bool:
    return color is not None and color.value is not None and color.alpha != 0


def _dark(color) -> bool:
    """True for a painted colour that marks (luminance ≤ 0.5); False for none/light/transparent."""
    if not _painted(color):
        return False
    return (0.299 * color.red + 0.587 * color.green + 0.114 * color.blue) / 255.0 <= 0.5


def _stroke_width(el, se, m: np.ndarray) -> tuple[float, float, bool]:
    """(width in the element's user space, its equivalent width in page px — scaled by
    sqrt|det| of the transform —, non-scaling) of the stroke; 0 when there is none.
    A non-scaling stroke's width is in page px already."""
    if not _painted(el.stroke):
        return 0.0, 0.0, False
    if "non-scaling-stroke" in (el.values.get("vector-effect") or ""):
        raw = el.values.get("stroke-width", "1")
        w = float(se.Length(raw).value(ppi=_SVG_PPI)) if raw else 1.0
        return w, w, True
    w = el.stroke_width
    w = float(w) if w is not None and math.isfinite(float(w)) and float(w) > 0 else 0.0
    return w, w * math.sqrt(abs(float(np.linalg.det(m[:, :2])))), False


def _page(svg) -> tuple[float, float] | None:
    """(width, height) px of the page that a renderer clips to, None when the file gives
    neither a size nor a viewBox (then nothing is clipped)."""
    if svg.values.get("width") is None and svg.values.get("height") is None \
            and getattr(svg, "viewbox", None) is None:
        return None
    w, h = (getattr(svg, k, None) for k in ("width", "height"))
    if not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in (w, h)):
        return None
    return float(w), float(h)


def _clip_to_page(filled, thin: list[np.ndarray], page, tol_px: float):
    """(filled ∩ page, the thin lines' pieces on the page, warning or None)."""
    if page is None:
        return filled, thin, None
    box = shapely.box(0.0, 0.0, *page)
    if not len(thin) and box.contains(filled):
        return filled, thin, None
    kept = filled.intersection(box)
    lost_mm2 = (filled.area - kept.area) * MM_PER_PX ** 2
    pieces, lost_mm = [], 0.0
    for q in thin:
        line = shapely.LineString(q) if len(q) >= 2 else None
        if line is None or box.contains(line):
            pieces.append(q)
            continue
        inside = line.intersection(box)
        lost_mm += (line.length - inside.length) * MM_PER_PX
        pieces += [np.asarray(g.coords)[:, :2] for g in shapely.get_parts(inside)
                   if g.geom_type == "LineString" and g.length > 0]
    if lost_mm2 <= (tol_px * MM_PER_PX) ** 2 and lost_mm <= tol_px * MM_PER_PX:
        return filled, thin, None
    w, h = (v * MM_PER_PX for v in page)
    return kept, pieces, (f"warning: content outside the page ({w:.4g} × {h:.4g} mm) clipped "
                          f"as a renderer clips it: {lost_mm2:.4g} mm² of fill and "
                          f"{lost_mm:.4g} mm of lines left out")


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
    ``notes``; what is left out (content beyond the page, text, images) is said there in a
    note starting with "warning:"."""
    import svgelements as se

    path = Path(path)
    _check_file(path)
    try:
        svg = se.SVG.parse(str(path), reify=False, ppi=_SVG_PPI)
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

        skipped: dict[str, int] = {}
        for el in svg.elements():
            if isinstance(el, (se.Text, se.SVGImage)):
                kind = "text" if isinstance(el, se.Text) else "image"
                skipped[kind] = skipped.get(kind, 0) + 1
            if not isinstance(el, se.Shape) or el.values.get("visibility") in ("hidden",
                                                                               "collapse"):
                continue
            tag = el.values.get("tag", "shape")
            m = _matrix(el.transform)
            check_finite(m, path, f"a <{tag}>'s transform")
            scale = float(np.linalg.norm(m[:, :2], 2))
            if not scale > 0:
                continue  # scaled to nothing: nothing is drawn
            local = _svg_subpaths(el, se, tol_px / scale, budget, f"a <{tag}>")
            subs = [(_apply(m, q), c) for q, c in local]
            if not subs:
                continue
            check_extent(np.concatenate([q for q, _ in subs]) * MM_PER_PX, path, f"a <{tag}>")
            if _painted(el.fill):
                rule = "evenodd" if el.values.get("fill-rule") == "evenodd" else "nonzero"
                rings = [p[:-1] if c else p for p, c in subs if len(p) >= 3]
                if rings:
                    paint(region(rings, rule), _dark(el.fill))
            w_user, w_px, fixed = _stroke_width(el, se, m)
            if w_px <= 0:
                continue
            w_mm = w_px * MM_PER_PX
            widths.add(round(w_mm, 9))
            if w_mm >= beam_mm:
                cap = el.values.get("stroke-linecap", "butt")
                join = el.values.get("stroke-linejoin", "miter")
                limit = float(el.values.get("stroke-miterlimit", 4) or 4)
                # the outline is drawn in the element's user space, then transformed
                g = shapely.unary_union([stroke_region(q[:-1] if c else q, w_user, cap, join,
                                                       limit, c and len(q) >= 4)
                                         for q, c in (subs if fixed else local)])
                if not fixed:
                    g = shapely.affinity.affine_transform(g, [*m[0, :2], *m[1, :2], *m[:, 2]])
                paint(g, _dark(el.stroke))
                n_stroke_areas += 1
            elif _dark(el.stroke):
                thin.extend(p for p, _ in subs if len(p) >= 2)
        filled = shapely.unary_union([filled, *dark])
        # slivers thinner than the tolerance (a fill of a straight path, an erasure's seam)
        parts = shapely.get_parts(filled)
        filled = shapely.unary_union(parts[shapely.area(parts) > 0.5 * tol_px
                                           * shapely.length(parts)])
        had_content = not filled.is_empty or bool(thin)
        page = _page(svg)
        filled, thin, clipped = _clip_to_page(filled, thin, page, tol_px)
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
    if clipped:
        notes.append(clipped)
    for kind, n in skipped.items():
        notes.append(f"warning: {n} <{kind}> element(s) not marked"
                     + (" (convert text to paths)" if kind == "text" else ""))
    contours = tuple(to_mm(c) for c in contours_of(filled))
    if had_content and not contours and not thin:
        w, h = (v * MM_PER_PX for v in page)
        raise FormatError(f"{path}: everything it draws lies outside its page ({w:.4g} × "
                          f"{h:.4g} mm)")
    return _non_empty(Pattern(contours, tuple(to_mm(p) for p in thin), path.name,
                              notes=tuple(notes), stroke_widths=tuple(sorted(widths)),
                              beam_mm=beam_mm),
                      path, "filled or stroked shapes")
