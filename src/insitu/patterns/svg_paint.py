"""SVG paint as the laser marks it.

A paint is *flat* when it is one opaque colour (a gradient whose stops are all one colour
counts): flat paints stay vector — a dark one (luminance ≤ 0.5) adds to the marked region, a
light one erases what was painted before it. Everything else — gradients, patterns,
opacity below 1 (of the element, its fill or stroke, or a group), masks, filters, images —
is marked by what it looks like: the document is rendered by cairosvg over those elements'
regions at the beam's resolution, and the render, clipped to the regions, is thresholded at
50 % grey (``paint="threshold"``) or dithered (``paint="dither"``, ordered 8 × 8 Bayer
dots). An element whose paint shows shades the threshold loses gets one warning naming it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely
import shapely.affinity

from insitu.patterns.svg_doc import href, local, opacity, url_id

MAX_RASTER_PX = 24_000_000


@dataclass(frozen=True)
class Paint:
    """A resolved fill or stroke. ``lum``: luminance 0–1 of a flat paint (None otherwise);
    ``alpha``: its opacity; ``server``: "gradient" or "pattern" for a paint server;
    ``mean``: the luminance it shows on white on average (for thin strokes)."""

    lum: float | None = None
    alpha: float = 1.0
    server: str | None = None
    mean: float = 1.0

    @property
    def none(self) -> bool:
        return self.server is None and (self.lum is None or self.alpha <= 0)


NONE = Paint()


@dataclass
class Item:
    """One painted thing, page px: ``region`` its area (shapely), ``lines`` thin dark stroke
    centre lines ((N, 2) each), ``lum`` the luminance of a flat opaque paint or None for one
    the renderer draws (``why`` says what it is), ``what`` the element for notes."""

    region: object
    lum: float | None
    what: str
    why: str = ""
    lines: list = field(default_factory=list)

    def mapped(self, m: np.ndarray) -> Item:
        """This item under the (2, 3) affine ``m``."""
        r = shapely.affinity.affine_transform(self.region, [*m[0, :2], *m[1, :2], *m[:, 2]])
        with np.errstate(over="ignore", invalid="ignore"):
            lines = [q @ m[:, :2].T + m[:, 2] for q in self.lines]
        return Item(r, self.lum, self.what, self.why, lines)


def luminance(rgb) -> float:
    r, g, b = rgb
    return (0.299 * r + 0.587 * g + 0.114 * b) / 255.0


def colour(value: str, style: dict):
    """(r, g, b, alpha) of a CSS colour (``currentColor`` from ``style``), None for none."""
    import svgelements as se

    v = (value or "").strip()
    if v.lower() == "currentcolor":
        v = style.get("color", "black")
    if not v or v.lower() in ("none", "transparent"):
        return None
    try:
        c = se.Color(v)
    except (ValueError, TypeError):
        return None
    if c.value is None:
        return None
    return c.red, c.green, c.blue, c.alpha / 255.0


def _stops(el, doc, depth: int = 0) -> list:
    """(rgb, opacity) of a gradient's stops, following ``href`` to the one that has them."""
    stops = [s for s in el if local(s.tag) == "stop"]
    if not stops and depth < 16:
        ref = doc.ids.get(href(el) or "")
        return _stops(ref, doc, depth + 1) if ref is not None else []
    out = []
    for s in stops:
        st = doc.style_of(s)
        c = colour(st.get("stop-color", "black"), st) or (0, 0, 0, 0.0)
        out.append((c[:3], c[3] * opacity(st.get("stop-opacity", 1))))
    return out


def resolve(value: str | None, opacity_value, style: dict, doc) -> Paint:
    """The paint ``value`` (a colour, ``url(#id) fallback`` or none) with its opacity."""
    a = opacity(opacity_value)
    ident = url_id(value)
    if ident is not None:
        server = doc.ids.get(ident)
        kind = local(server.tag) if server is not None else None
        if kind in ("linearGradient", "radialGradient"):
            stops = _stops(server, doc)
            if not stops:
                return NONE                                 # no stops: paints nothing
            if all(s == stops[0] for s in stops):           # one colour: flat
                return Paint(luminance(stops[0][0]), a * stops[0][1])
            mean = float(np.mean([1 - o * a * (1 - luminance(c)) for c, o in stops]))
            return Paint(None, a, "gradient", mean)
        if kind == "pattern":
            return Paint(None, a, "pattern", 0.5)
        fallback = (value or "").split(")", 1)[-1].strip()
        value = fallback or "none"
    c = colour(value, style)
    if c is None:
        return NONE
    lum, alpha = luminance(c[:3]), a * c[3]
    return Paint(lum, alpha, None, 1 - alpha * (1 - lum))


def composite(items: list[Item], mode: str = "threshold") -> tuple[object, list, object]:
    """(the dark region of the flat paints, their thin dark lines, the union of the regions
    the renderer draws), page px. Flat paints in order: dark adds, light erases what was
    painted before it — each dark piece is cut once, by the union of the light paints after
    it that meet its box. Dithered, a flat light paint that is not white is drawn by the
    renderer too (its shade as sparse dots)."""
    dark, light, lines, raster = [], [], [], []
    for n, it in enumerate(items):
        if it.lum is None or (mode == "dither" and 0.5 < it.lum < 0.98):
            if not it.region.is_empty:
                raster.append(it.region)
            continue
        lines.extend(it.lines)
        if not it.region.is_empty:
            (dark if it.lum <= 0.5 else light).append((n, it.region))
    if not dark:
        return shapely.Polygon(), lines, shapely.unary_union(raster)
    if light:
        order = np.array([n for n, _ in light])
        boxes = np.array([g.bounds for _, g in light])
        for k, (n, g) in enumerate(dark):
            b = g.bounds
            hit = np.flatnonzero((order > n) & (boxes[:, 0] <= b[2]) & (boxes[:, 2] >= b[0])
                                 & (boxes[:, 1] <= b[3]) & (boxes[:, 3] >= b[1]))
            if len(hit):
                dark[k] = (n, g.difference(shapely.unary_union([light[h][1] for h in hit])))
    return shapely.unary_union([g for _, g in dark]), lines, shapely.unary_union(raster)


def _sanitized(root):
    """A copy of the document without references to ids it does not hold (a browser draws
    nothing for them; cairosvg would stop)."""
    import copy
    import re

    from insitu.patterns.svg_doc import XLINK_HREF

    ids = {el.get("id") for el in root.iter() if el.get("id")}
    url = re.compile(r"url\(\s*['\"]?#([^)'\"]+)['\"]?\s*\)")
    if not any(m[1] not in ids for el in root.iter() for v in el.attrib.values()
               for m in url.finditer(v)) and not any(
            (el.get("href") or el.get(XLINK_HREF) or "#")[1:] not in ids
            for el in root.iter() if (el.get("href") or el.get(XLINK_HREF) or "").startswith("#")):
        return root
    out = copy.deepcopy(root)
    for el in out.iter():
        for k, v in list(el.attrib.items()):
            if k in ("href", XLINK_HREF) and v.startswith("#") and v[1:] not in ids:
                del el.attrib[k]
            elif "url(" in v:
                el.set(k, url.sub(lambda m: m[0] if m[1] in ids else "none", v))
    return out


def rendered(root, page: tuple[float, float], box, pixel_px: float) -> np.ndarray:
    """(H, W) float64 grey 0–1 (0 black) of the document ``root`` rendered by cairosvg on
    white, its page ``page`` (w, h) px, over ``box`` (x0, y0, x1, y1 page px) at ``pixel_px``
    page px per pixel."""
    import copy
    import xml.etree.ElementTree as ET

    import cairosvg
    import cv2

    from insitu.patterns.svg_doc import SVG_NS

    ET.register_namespace("", SVG_NS)
    ET.register_namespace("xlink", "http://www.w3.org/1999/xlink")
    inner = copy.copy(_sanitized(root))
    inner.attrib = {k: v for k, v in root.attrib.items() if k not in ("x", "y")}
    inner.set("width", repr(page[0]))
    inner.set("height", repr(page[1]))
    x0, y0, x1, y1 = box
    w = max(1, int(np.ceil((x1 - x0) / pixel_px)))
    h = max(1, int(np.ceil((y1 - y0) / pixel_px)))
    vw, vh = w * pixel_px, h * pixel_px
    doc = (f'<svg xmlns="{SVG_NS}" width="{w}" height="{h}" viewBox="{x0!r} {y0!r} {vw!r} '
           f'{vh!r}" preserveAspectRatio="none" shape-rendering="crispEdges" '
           'text-rendering="crispEdges">').encode() + ET.tostring(inner) + b"</svg>"
    png = cairosvg.svg2png(bytestring=doc, output_width=w, output_height=h,
                           background_color="white")
    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).astype(np.float64) / 255.0


def _raster_mask(geom, box, pixel: float, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool: the pixels whose centres lie in ``geom`` (page px) on the grid of
    ``box`` (x0, y0, …) at ``pixel`` page px — sampled by cairo as the render is."""
    import cairocffi as cairo

    h, w = shape
    surface = cairo.ImageSurface(cairo.FORMAT_A8, w, h)
    ctx = cairo.Context(surface)
    ctx.set_antialias(cairo.ANTIALIAS_NONE)
    ctx.set_fill_rule(cairo.FILL_RULE_EVEN_ODD)
    ctx.scale(1.0 / pixel, 1.0 / pixel)
    ctx.translate(-box[0], -box[1])
    for poly in shapely.get_parts(geom):
        if poly.geom_type != "Polygon" or poly.is_empty:
            continue
        for ring in (poly.exterior, *poly.interiors):
            pts = np.asarray(ring.coords)[:, :2]
            ctx.move_to(*pts[0])
            for x, y in pts[1:]:
                ctx.line_to(x, y)
            ctx.close_path()
    ctx.fill()
    surface.flush()
    stride = surface.get_stride()
    data = np.frombuffer(surface.get_data(), np.uint8).reshape(h, stride)[:, :w]
    return data > 127


def apply_renderer(root, page, path, dark, where, items: list[Item], beam_px: float,
                   mode: str):
    """(the marked region, scan lines of dithered dots, warnings, the pixel used), page px:
    ``dark`` (the flat paints) outside ``where``, the render of the document inside it —
    thresholded at 50 % grey, or dithered."""
    from insitu.patterns.raster import _BAYER8, mask_region, scan_lines

    x0, y0, x1, y1 = where.bounds
    pixel, notes = beam_px, []
    n = (x1 - x0) * (y1 - y0) / pixel ** 2
    if n > MAX_RASTER_PX:
        pixel *= float(np.sqrt(n / MAX_RASTER_PX))
        notes.append(f"warning: the shaded paints cover {(x1 - x0) * 25.4 / 96:.4g} × "
                     f"{(y1 - y0) * 25.4 / 96:.4g} mm: rendered at {pixel * 25.4 / 96:.3g} mm "
                     "pixels (coarser than the beam)")
    # a grid whose pixel centres miss round coordinates: a shared edge of two shapes on a
    # centre would leave a seam (a renderer without anti-aliasing fills neither side)
    x0, y0 = x0 - 0.3819 * pixel, y0 - 0.2761 * pixel
    box = (x0, y0, x1, y1)
    gray = rendered(root, page or (x1, y1), box, pixel)
    h, w = gray.shape
    inside = _raster_mask(where, box, pixel, (h, w))
    if mode == "dither":
        t = (_BAYER8[np.arange(h)[:, None] % 8, np.arange(w)[None, :] % 8] + 0.5) / 64.0
        marked = (gray < t) & inside
    else:
        marked = _edges_from_inside(gray < 0.5, inside)
    flip = [1.0, 0.0, 0.0, -1.0, x0, y0 + h * pixel]          # y up (mask_region) → page px
    lines = []
    if mode == "dither":
        for q in scan_lines(marked, pixel):
            lines.append(np.column_stack([q[:, 0] + x0, y0 + h * pixel - q[:, 1]]))
        region = shapely.Polygon()
    else:
        region = shapely.affinity.affine_transform(mask_region(marked, pixel), flip)
        region = region.intersection(where)
    out = shapely.unary_union([dark.difference(where), region])
    return out, lines, notes + _shade_warnings(items, gray, box, pixel, mode), pixel


def _edges_from_inside(dark: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """The dark pixels, with the band along the regions' edges (where the render mixes the
    paint with what lies beyond the edge) taking the value of the pixels just inside: the
    edge itself is the exact vector one the caller cuts with. Regions too thin to have an
    inside keep their thresholded pixels."""
    import cv2

    k3, k5 = np.ones((3, 3), np.uint8), np.ones((5, 5), np.uint8)
    inside8 = inside.astype(np.uint8)
    touch = cv2.dilate(inside8, k3).astype(bool)
    core = cv2.erode(inside8, k3).astype(bool)
    dark_core = (dark & core).astype(np.uint8)
    near_core = cv2.dilate(core.astype(np.uint8), k5).astype(bool)
    band = touch & ~core
    band_dark = band & (cv2.dilate(dark_core, k5).astype(bool) | (dark & ~near_core))
    return (dark & core) | band_dark


def _shade_warnings(items: list[Item], gray: np.ndarray, box, pixel: float,
                    mode: str) -> list[str]:
    """One warning per element whose render shows grey a threshold loses (up to 5, then a
    count), none when dithering."""
    if mode == "dither":
        return []
    named = []
    for it in [i for i in items if i.lum is None][:500]:
        m = _raster_mask(it.region, box, pixel, gray.shape)
        g = gray[m]
        painted = g[g < 0.97]
        if len(painted) >= 16 and np.mean((painted > 0.15) & (painted < 0.85)) > 0.1:
            named.append(f"{it.what} ({it.why})")
    named = list(dict.fromkeys(named))
    out = [f"warning: {n}: shades of grey marked where darker than 50 % (--paint dither "
           "keeps them as dots)" for n in named[:5]]
    if len(named) > 5:
        out.append(f"warning: {len(named) - 5} more elements with shades marked where "
                   "darker than 50 %")
    return out
