"""The SVG rendering tree walked as a browser walks it, into painted items (page px).

Groups, nested ``<svg>`` viewports (viewBox, preserveAspectRatio, overflow clip),
``<switch>``, ``<use>`` of shapes, groups, symbols and svgs (each referenced element drawn
once per style and scale and moved for the other uses), ``display``/``visibility``, clip
paths as geometry (shapely intersections under ``clip-rule``), opacity, masks and filters
(their elements drawn by the renderer), shapes (:mod:`insitu.patterns.svg_shapes`), text
(:mod:`insitu.patterns.svg_text`) and images (drawn by the renderer).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import shapely
import shapely.affinity

from insitu.patterns.svg_doc import (
    XLINK_HREF,
    cascade,
    compose,
    computed,
    href,
    length,
    local,
    matrix,
    opacity,
    translate,
    url_id,
    viewbox_matrix,
    viewbox_of,
)
from insitu.patterns.svg_paint import Item
from insitu.patterns.vector import Budget

_NOT_DRAWN = {"defs", "clipPath", "mask", "marker", "pattern", "linearGradient",
              "radialGradient", "symbol", "style", "title", "desc", "metadata", "filter",
              "script", "font", "font-face", "cursor", "view", "animate", "set",
              "animateMotion", "animateColor", "animateTransform", "flowRegion",
              "color-profile", "altGlyphDef"}
SHAPES = ("path", "rect", "circle", "ellipse", "line", "polyline", "polygon")


@dataclass(frozen=True)
class Ctx:
    """Where an element is drawn: ``ctm`` (2, 3) user space → page px, the parent's
    computed ``style``, the ``viewport`` (w, h) px percentages refer to, ``why`` a group's
    reason for the renderer to draw its content ("" if none), ``clip`` True inside a
    clipPath (shapes give their area, unpainted), ``refs`` the use/marker ids in progress."""

    ctm: np.ndarray
    style: dict | None
    viewport: tuple[float, float]
    why: str = ""
    clip: bool = False
    refs: tuple = ()


class Doc:
    """A parsed document and what the walk collects: ids, the cascade, styles along the
    document tree, counts of what was skipped, the stroke widths met, caches."""

    def __init__(self, root, path: Path, tol_px: float, beam_px: float):
        self.root, self.path, self.tol_px, self.beam_px = root, path, tol_px, beam_px
        self.ids = {el.get("id"): el for el in root.iter() if el.get("id")}
        self.decl = cascade(root)
        self.parent = {c: p for p in root.iter() for c in p}
        self.budget = Budget(path)
        self.skipped: Counter = Counter()
        self.effects: dict[str, str] = {}   # element → the effect not rendered (a filter)
        self.widths: set[float] = set()
        self.stroke_areas = 0
        self.fonts: dict[str, str] = {}     # family asked → the font used instead
        self.cache: dict = {}
        self._styles: dict = {}
        self._nth: dict = {}
        seen: Counter = Counter()
        for el in root.iter():
            name = local(el.tag)
            if name:
                seen[name] += 1
                self._nth[el] = seen[name]

    def style_of(self, el) -> dict:
        """The computed style of ``el`` in the document tree (not through a use)."""
        if el not in self._styles:
            p = self.parent.get(el)
            self._styles[el] = computed(self.decl.get(el, {}),
                                        self.style_of(p) if p is not None else None)
        return self._styles[el]

    def describe(self, el) -> str:
        """``<path id="logo">`` or ``<path> #3`` (the third path of the file)."""
        name = local(el.tag) or "element"
        return f'<{name} id="{el.get("id")}">' if el.get("id") else \
            f"<{name}> #{self._nth.get(el, 0)}"


def inverse(m: np.ndarray) -> np.ndarray | None:
    a = m[:, :2]
    if abs(float(np.linalg.det(a))) < 1e-300:
        return None
    ai = np.linalg.inv(a)
    return np.column_stack([ai, -ai @ m[:, 2]])


def apply(m: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(N, 2) points under the (2, 3) affine ``m``; beyond float range inf or nan, without a
    warning (refused later as not finite, naming the element)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return pts @ m[:, :2].T + m[:, 2]


def rect_region(m: np.ndarray, x: float, y: float, w: float, h: float):
    return shapely.Polygon(apply(m, np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]])))


def clipped(items: list[Item], g) -> list[Item]:
    """``items`` cut to the region ``g`` (page px): areas intersected, lines cut."""
    out = []
    for it in items:
        lines = []
        for q in it.lines:
            part = shapely.LineString(q).intersection(g) if len(q) >= 2 else None
            lines += [np.asarray(p.coords)[:, :2] for p in shapely.get_parts(part)
                      if part is not None and p.geom_type == "LineString" and p.length > 0]
        region = it.region.intersection(g) if not it.region.is_empty else it.region
        if not region.is_empty or lines:
            out.append(Item(region, it.lum, it.what, it.why, lines))
    return out


def children(doc: Doc, el, c: Ctx) -> list[Item]:
    out = []
    for child in el:
        out += walk(doc, child, c)
    return out


def _passes(el) -> bool:
    """Conditional processing (on any element, and choosing a <switch>'s child): no
    extensions asked, only SVG 1.1's features, English or no language."""
    if (el.get("requiredExtensions") or "").strip():
        return False
    features = el.get("requiredFeatures")
    if features is not None and not (features.split() and all(
            f.startswith("http://www.w3.org/TR/SVG11/feature#") for f in features.split())):
        return False                         # an empty list or a feature SVG 1.1 does not name
    lang = el.get("systemLanguage")
    return lang is None or any(x.strip().lower().startswith("en") for x in lang.split(","))


def viewport(doc: Doc, el, c: Ctx, x: float, y: float, w: float, h: float) -> list[Item]:
    """The content of a nested <svg> or a used <symbol>: its viewBox fitted into the
    viewport (x, y, w, h) of ``c``'s user space, clipped there unless ``overflow`` shows it."""
    if not (w > 0 and h > 0):
        return []
    vb = viewbox_of(el)
    m = compose(c.ctm, translate(x, y))
    if vb is not None:
        m = compose(m, viewbox_matrix(vb, w, h, el.get("preserveAspectRatio")))
    items = children(doc, el, replace(c, ctm=m, viewport=(vb[2], vb[3]) if vb else (w, h)))
    if doc.decl.get(el, {}).get("overflow", "hidden") in ("hidden", "scroll", "clip"):
        items = clipped(items, rect_region(c.ctm, x, y, w, h))
    return items


def _use(doc: Doc, el, c: Ctx, style: dict) -> list[Item]:
    ref = doc.ids.get(href(el) or "")
    if ref is None or ref.get("id") in c.refs or len(c.refs) > 32:
        return []
    vw, vh = c.viewport
    fp = float(style["font-size"])
    m = compose(c.ctm, translate(length(el.get("x"), vw, fp), length(el.get("y"), vh, fp)))
    scale = float(np.sqrt(abs(np.linalg.det(m[:, :2]))))
    key = (ref.get("id"), tuple(sorted(style.items())), el.get("width"), el.get("height"),
           c.why, c.clip, round(float(np.log(scale)) if scale > 0 else 0.0, 9))
    if key in doc.cache:
        first, items = doc.cache[key]
        inv = inverse(first)
        return [] if inv is None else [it.mapped(compose(m, inv)) for it in items]
    cc = replace(c, ctm=m, style=style, refs=c.refs + (ref.get("id"),))
    kind = local(ref.tag)
    if kind in ("symbol", "svg"):
        sty = computed(doc.decl.get(ref, {}), style)
        if sty.get("display") == "none":
            return []
        w = length(el.get("width") or ref.get("width") or "100%", vw, fp)
        h = length(el.get("height") or ref.get("height") or "100%", vh, fp)
        x, y = ((length(ref.get("x"), vw, fp), length(ref.get("y"), vh, fp)) if kind == "svg"
                else (0.0, 0.0))
        items = viewport(doc, ref, replace(cc, style=sty), x, y, w, h)
    else:
        items = walk(doc, ref, cc)
    doc.cache[key] = (m, items)
    return items


def _clip_region(doc: Doc, el, c: Ctx, items: list[Item]):
    """The clip path ``el`` references as a region in page px (None: no valid clip)."""
    clip = doc.ids.get(url_id(doc.decl.get(el, {}).get("clip-path") or
                              c.style.get("clip-path")) or "")
    if clip is None or local(clip.tag) != "clipPath" or clip.get("id") in c.refs:
        return None
    m = c.ctm
    if clip.get("clipPathUnits") == "objectBoundingBox":
        inv = inverse(m)
        g = shapely.unary_union([it.region for it in items])
        if inv is None or g.is_empty:
            return shapely.Polygon()
        x0, y0, x1, y1 = shapely.affinity.affine_transform(
            g, [*inv[0, :2], *inv[1, :2], *inv[:, 2]]).bounds
        m = compose(m, np.array([[x1 - x0, 0, x0], [0, y1 - y0, y0]]))
    m = compose(m, matrix(clip.get("transform")))
    cc = Ctx(m, doc.style_of(clip), c.viewport, "", True, c.refs + (clip.get("id"),))
    region = shapely.unary_union([it.region for it in children(doc, clip, cc)])
    outer = _clip_region(doc, clip, replace(cc, ctm=c.ctm), items) \
        if url_id(doc.decl.get(clip, {}).get("clip-path")) else None
    return region if outer is None else region.intersection(outer)


def walk(doc: Doc, el, c: Ctx) -> list[Item]:
    """The items ``el`` and its subtree paint, in painting order."""
    from insitu.patterns import svg_shapes, svg_text

    name = local(el.tag)
    if name is None or name in _NOT_DRAWN or not _passes(el):
        return []
    style = computed(doc.decl.get(el, {}), c.style)
    if style.get("display") == "none":
        return []
    op = 1.0 if c.clip else opacity(style.get("opacity", 1))
    if op <= 0:
        return []
    why = c.why
    if not c.clip:
        if op < 1:
            why = why or f"opacity {op:g}"
        if url_id(style.get("mask")) in doc.ids:
            why = why or "mask"
        fid = url_id(style.get("filter"))
        if fid in doc.ids:
            why = why or "filter"
            kinds = sorted({local(f.tag) or "" for f in doc.ids[fid]} - {""})
            doc.effects[doc.describe(el)] = (f"filter ({', '.join(kinds[:3])}) drawn as cairosvg "
                                             "draws it: blur and lighting are not applied")
    c = replace(c, ctm=compose(c.ctm, matrix(el.get("transform"))), why=why)
    if name in ("g", "a"):
        items = children(doc, el, replace(c, style=style))
    elif name == "switch":
        first = next((ch for ch in el if local(ch.tag) and local(ch.tag) not in _NOT_DRAWN
                      and _passes(ch)), None)
        items = walk(doc, first, replace(c, style=style)) if first is not None else []
    elif name == "svg":
        vw, vh = c.viewport
        fp = float(style["font-size"])
        items = viewport(doc, el, replace(c, style=style), length(el.get("x"), vw, fp),
                         length(el.get("y"), vh, fp), length(el.get("width", "100%"), vw, fp),
                         length(el.get("height", "100%"), vh, fp))
    elif name == "use":
        items = _use(doc, el, c, style)
    elif name in SHAPES:
        items = svg_shapes.shape_items(doc, el, name, c, style)
    elif name in ("text", "flowRoot"):
        items = svg_text.text_items(doc, el, name, c, style)
    elif name == "image" and not c.clip:
        vw, vh = c.viewport
        x, y, w, h = (length(el.get(k), r) for k, r in (("x", vw), ("y", vh), ("width", vw),
                                                          ("height", vh)))
        link = (el.get("href") or el.get(XLINK_HREF) or "").strip()
        items = [Item(rect_region(c.ctm, x, y, w, h), None, doc.describe(el), "image")] \
            if w > 0 and h > 0 and style.get("visibility", "visible") == "visible" else []
        if items and not link.startswith("data:"):
            doc.effects[doc.describe(el)] = (f"links the picture {link[:40]!r}: not marked "
                                             "(embed it in the SVG)")
            items = []
    else:
        doc.skipped[name] += 1
        items = []
    if url_id(style.get("clip-path")) and items:
        g = _clip_region(doc, el, replace(c, style=style), items)
        if g is not None:
            items = clipped(items, g)
    return items
