"""SVG shapes (path, rect, circle, ellipse, line, polyline, polygon) into painted items:
the fill (``fill-rule``), the stroke — dashed by ``stroke-dasharray``/``-offset``, outlined
in the element's user space with its caps, joins and miter limit, then transformed (a stroke
at least ``beam`` wide; a thinner dark one is a line along its centre) — and the markers at
its vertices (``marker-start/-mid/-end``: orient, markerUnits, viewBox, refX/refY, clipped
to the marker's viewport)."""

from __future__ import annotations

import math

import numpy as np
import shapely
import shapely.affinity

from insitu.patterns.model import region, stroke_region
from insitu.patterns.svg_doc import (
    compose,
    length,
    local,
    numbers,
    translate,
    url_id,
    viewbox_matrix,
    viewbox_of,
)
from insitu.patterns.svg_paint import Item, resolve
from insitu.patterns.svg_walk import Ctx, apply, children, clipped, inverse, rect_region
from insitu.patterns.vector import (
    MM_PER_PX,
    _arc_steps,
    bezier_points,
    bezier_steps,
    check_extent,
    check_finite,
    dashed,
)

_NUMERIC = ("x", "y", "width", "height", "r", "rx", "ry", "cx", "cy", "x1", "y1", "x2", "y2")


def subpaths(shape, se, tol: float, budget, what: str) -> list[tuple[np.ndarray, bool]]:
    """Flatten one svgelements shape, in its own user space, into (points, closed) subpaths
    within ``tol`` of the curves; a lone move-to is a one-point subpath (a dot under a round
    cap). Every segment's points must be finite, and its chords are taken from ``budget``."""
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
        if isinstance(seg, (se.QuadraticBezier, se.CubicBezier)):
            n = bezier_steps(ctrl, tol)
            budget.take(n, what)
            pts.extend(map(tuple, bezier_points(ctrl, tol)[1:]))
        elif isinstance(seg, se.Arc):
            check_finite([(seg.rx, seg.ry), (seg.sweep, 0.0)], budget.path, what)
            n = _arc_steps(max(abs(seg.rx), abs(seg.ry)), seg.sweep, tol)
            budget.take(n, what)
            pts.extend(map(tuple, np.asarray(seg.npoint(np.linspace(0, 1, n + 1)))[1:, :2]))
        else:
            budget.take(1, what)
            pts.append((seg.end.x, seg.end.y))
            if isinstance(seg, se.Close):
                closed = True
                flush()
                pts, closed = [], False
    flush()
    return out


def geometry(el, name: str, style: dict, viewport: tuple[float, float]):
    """The svgelements shape of a basic shape or path in its user space, None when it draws
    nothing (a rect of zero width, a circle of radius 0, bad path data)."""
    import svgelements as se

    vw, vh = viewport
    diag = math.sqrt((vw * vw + vh * vh) / 2)
    fp = float(style["font-size"])

    def n(key, ref):
        return length(el.get(key), ref, fp)

    try:
        if name == "path":
            return se.Path(el.get("d") or "")
        if name == "rect":
            w, h = n("width", vw), n("height", vh)
            rx, ry = el.get("rx"), el.get("ry")
            rx, ry = (n("rx", vw) if rx else None), (n("ry", vh) if ry else None)
            rx, ry = (rx if rx is not None else ry or 0.0), (ry if ry is not None else rx or 0.0)
            if w <= 0 or h <= 0:
                return None
            return se.Rect(n("x", vw), n("y", vh), w, h, min(max(rx, 0), w / 2),
                           min(max(ry, 0), h / 2))
        if name == "circle":
            r = n("r", diag)
            return se.Circle(n("cx", vw), n("cy", vh), r) if r > 0 else None
        if name == "ellipse":
            rx, ry = n("rx", vw), n("ry", vh)
            return se.Ellipse(n("cx", vw), n("cy", vh), rx, ry) if rx > 0 and ry > 0 else None
        if name == "line":
            return se.Path(f"M{n('x1', vw)!r},{n('y1', vh)!r} L{n('x2', vw)!r},{n('y2', vh)!r}")
        v = numbers(el.get("points"))
        if len(v) < 4:
            return None
        pts = " L".join(f"{v[i]!r},{v[i + 1]!r}" for i in range(0, len(v) - 1, 2))
        return se.Path(f"M{pts}" + (" Z" if name == "polygon" else ""))
    except (ValueError, TypeError, IndexError):
        return None


def _flat(paint, c: Ctx, what: str, g, kind: str) -> Item:
    """The item of region ``g`` under ``paint``: flat (vector) or drawn by the renderer."""
    if paint.server is None and paint.alpha >= 1 and not c.why:
        return Item(g, paint.lum, what)
    return Item(g, None, what, c.why or paint.server or f"{kind}-opacity {paint.alpha:g}")


def _dashes(style: dict, fp: float, diag: float) -> tuple[list[float] | None, float]:
    raw = style.get("stroke-dasharray", "none") or "none"
    if raw.strip() == "none":
        return None, 0.0
    d = [length(x, diag, fp, -1.0) for x in raw.replace(",", " ").split()]
    if not d or any(x < 0 for x in d) or sum(d) <= 0:
        return None, 0.0
    return (d * 2 if len(d) % 2 else d), length(style.get("stroke-dashoffset", "0"), diag, fp)


def _stroke(doc, el, c: Ctx, style: dict, subs, what: str) -> list[Item]:
    """The stroke's items: its area, or its centre lines when thinner than the beam."""
    paint = resolve(style.get("stroke"), style.get("stroke-opacity", 1), style, doc)
    if paint.none:
        return []
    vw, vh = c.viewport
    diag, fp = math.sqrt((vw * vw + vh * vh) / 2), float(style["font-size"])
    m = c.ctm
    w = length(style.get("stroke-width", "1"), diag, fp, 1.0)
    fixed = "non-scaling-stroke" in (style.get("vector-effect") or "")
    w_px = w if fixed else w * math.sqrt(abs(float(np.linalg.det(m[:, :2]))))
    if not w_px > 0:
        return []
    doc.widths.add(round(w_px * MM_PER_PX, 9))
    src = [(apply(m, q), cl) for q, cl in subs] if fixed else subs
    pattern, offset = _dashes(style, fp, diag)
    pieces = []
    for q, cl in src:
        if pattern is None:
            pieces.append((q[:-1] if cl else q, cl and len(q) >= 4))
        else:
            pieces += [(p, False) for p in dashed(q[:-1] if cl else q, pattern, offset, cl)]
    if w_px >= doc.beam_px:
        cap = style.get("stroke-linecap", "butt")
        join = style.get("stroke-linejoin", "miter")
        limit = numbers(style.get("stroke-miterlimit", "4")) or [4.0]
        g = shapely.unary_union([stroke_region(q, w, cap, join, limit[0], cl)
                                 for q, cl in pieces])
        if not fixed:
            g = shapely.affinity.affine_transform(g, [*m[0, :2], *m[1, :2], *m[:, 2]])
        doc.stroke_areas += 1
        return [_flat(paint, c, what, g, "stroke")]
    if paint.mean > 0.5 or (c.why and paint.lum is not None and paint.lum > 0.5):
        return []
    lines = []
    for q, cl in pieces:
        if len(q) >= 2:
            q = q if fixed else apply(m, q)
            lines.append(np.vstack([q, q[:1]]) if cl else q)
    return [Item(shapely.Polygon(), 0.0, what, lines=lines)]


def _vertices(shape, se) -> list[tuple[np.ndarray, float | None, float | None]]:
    """(point, incoming angle, outgoing angle) of every vertex of a path, radians."""
    out: list[list] = []

    def angle(seg, t0, t1):
        a, b = seg.point(t0), seg.point(t1)
        return math.atan2(b.y - a.y, b.x - a.x) if (a.x, a.y) != (b.x, b.y) else None

    for seg in shape.segments(transformed=False):
        if isinstance(seg, se.Move):
            out.append([np.array([seg.end.x, seg.end.y]), None, None])
            continue
        if seg.start is None or seg.end is None or not out:
            continue
        out[-1][2] = angle(seg, 0.0, 1e-3)
        out.append([np.array([seg.end.x, seg.end.y]), angle(seg, 1 - 1e-3, 1.0), None])
    return [tuple(v) for v in out]


def _markers(doc, el, c: Ctx, style: dict, shape, w: float) -> list[Item]:
    import svgelements as se

    ids = {k: url_id(style.get(f"marker-{k}")) for k in ("start", "mid", "end")}
    if not any(ids.values()) or shape is None:
        return []
    verts = _vertices(shape, se)
    items: list[Item] = []
    for i, (p, a_in, a_out) in enumerate(verts):
        which = "start" if i == 0 else "end" if i == len(verts) - 1 else "mid"
        mk = doc.ids.get(ids[which] or "")
        if mk is None or local(mk.tag) != "marker" or mk.get("id") in c.refs:
            continue
        ins = [a for a in (a_in, a_out) if a is not None]
        if not ins:
            theta = 0.0
        elif len(ins) == 2:
            theta = math.atan2(math.sin(ins[0]) + math.sin(ins[1]),
                               math.cos(ins[0]) + math.cos(ins[1]))
        else:
            theta = ins[0]
        orient = mk.get("orient", "0").strip()
        if orient == "auto-start-reverse":
            theta += math.pi if which == "start" else 0.0
        elif orient != "auto":
            theta = math.radians((numbers(orient) or [0.0])[0])
        items += _marker(doc, mk, c, p, theta, w if mk.get("markerUnits") != "userSpaceOnUse"
                         else 1.0)
    return items


def _marker(doc, mk, c: Ctx, p, theta: float, scale: float) -> list[Item]:
    mw, mh = (length(mk.get(k, "3"), 0, 16, 3.0) for k in ("markerWidth", "markerHeight"))
    if not (mw > 0 and mh > 0 and scale > 0):
        return []
    vb = viewbox_of(mk)
    v = viewbox_matrix(vb, mw, mh, mk.get("preserveAspectRatio")) if vb else translate(0, 0)
    ref = apply(v, np.array([[length(mk.get("refX")), length(mk.get("refY"))]]))[0]
    ct, st = math.cos(theta), math.sin(theta)
    place = compose(c.ctm, np.array([[ct * scale, -st * scale, p[0]],
                                     [st * scale, ct * scale, p[1]]]))
    place = compose(place, translate(-ref[0], -ref[1]))
    m = compose(place, v)
    key = ("marker", mk.get("id"), round(scale, 9), c.why,
           round(float(np.log(abs(np.linalg.det(c.ctm[:, :2])) + 1e-300)), 9))
    if key in doc.cache:
        first, items = doc.cache[key]
        inv = inverse(first)
        return [] if inv is None else [it.mapped(compose(m, inv)) for it in items]
    cc = Ctx(m, doc.style_of(mk), (vb[2], vb[3]) if vb else (mw, mh), c.why, c.clip,
             c.refs + (mk.get("id"),))
    items = children(doc, mk, cc)
    if doc.decl.get(mk, {}).get("overflow", "hidden") in ("hidden", "scroll", "clip"):
        items = clipped(items, rect_region(place, 0, 0, mw, mh))
    doc.cache[key] = (m, items)
    return items


def shape_items(doc, el, name: str, c: Ctx, style: dict) -> list[Item]:
    """The fill, stroke and markers a shape paints (inside a clipPath: its area under
    ``clip-rule``)."""
    import svgelements as se

    if style.get("visibility", "visible") in ("hidden", "collapse"):
        return []
    what = doc.describe(el)
    check_finite([[length(el.get(k)), 0.0] for k in _NUMERIC if el.get(k)], doc.path, what)
    shape = geometry(el, name, style, c.viewport)
    if shape is None:
        return []
    scale = float(max(np.hypot(*c.ctm[:, 0]), np.hypot(*c.ctm[:, 1])))
    if not scale > 0:
        return []
    subs = subpaths(shape, se, doc.tol_px / scale, doc.budget, what)
    if not subs:
        return []
    page = [(apply(c.ctm, q), cl) for q, cl in subs]
    check_finite(np.concatenate([q for q, _ in page]), doc.path, what)
    check_extent(np.concatenate([q for q, _ in page]) * MM_PER_PX, doc.path, what)
    rings = [q[:-1] if cl else q for q, cl in page if len(q) >= 3]
    if c.clip:
        rule = "evenodd" if style.get("clip-rule") == "evenodd" else "nonzero"
        return [Item(region(rings, rule), 0.0, what)] if rings else []
    items = []
    fill = resolve(style.get("fill"), style.get("fill-opacity", 1), style, doc)
    if not fill.none and name != "line" and rings:
        rule = "evenodd" if style.get("fill-rule") == "evenodd" else "nonzero"
        items.append(_flat(fill, c, what, region(rings, rule), "fill"))
    items += _stroke(doc, el, c, style, subs, what)
    if name in ("path", "line", "polyline", "polygon"):
        vw, vh = c.viewport
        w = length(style.get("stroke-width", "1"), math.sqrt((vw * vw + vh * vh) / 2),
                   float(style["font-size"]), 1.0)
        items += _markers(doc, el, c, style, shape, w)
    return items
