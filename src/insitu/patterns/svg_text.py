"""SVG text outlined with its font: ``<text>`` with ``<tspan>`` (x, y, dx, dy and rotate per
character, text-anchor per chunk, letter- and word-spacing), ``<textPath>`` (glyphs along
the path from ``startOffset``, each turned to the path's direction at its middle) and
Inkscape's flowed text (``<flowRoot>``: words wrapped in the frame of its ``<flowRegion>``,
which is never marked; browsers do not draw it, so it comes with a warning).

Fonts are found through fontconfig as a renderer finds them (family list, weight, style); a
family that is not installed is outlined with fontconfig's choice, named in a warning.
Glyphs are placed by their advance widths (no kerning, as cairosvg places them).
"""

from __future__ import annotations

import functools
import math
import re

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns.model import region, stroke_region
from insitu.patterns.svg_doc import href, length, local, numbers
from insitu.patterns.svg_paint import Item, resolve
from insitu.patterns.svg_walk import apply

# Arabic, Hebrew, Syriac, Thaana, Indic, Thai, Lao, Tibetan, Myanmar: letters that join or
# reorder, which a renderer shapes (HarfBuzz) and a glyph-by-glyph layout cannot
_SHAPED = re.compile("[\u0590-\u08ff\u0900-\u0dff\u0e00-\u0fff\u1000-\u109f"
                     "\ufb1d-\ufdff\ufe70-\ufeff]")
_GENERIC = {"sans-serif": "DejaVu Sans", "serif": "DejaVu Serif", "monospace": "DejaVu Sans Mono",
            "cursive": "DejaVu Sans", "fantasy": "DejaVu Sans", "system-ui": "DejaVu Sans"}


@functools.lru_cache(maxsize=64)
def font_for(families: str, bold: bool, italic: bool) -> tuple[str, str | None]:
    """(font file, the family asked for when another one is used instead, else None) for a
    CSS ``font-family`` list."""
    from insitu.patterns.text import _fc_match, find_font

    names = [f.strip().strip("'\"") for f in families.split(",") if f.strip()] or ["sans-serif"]
    suffix = f":weight={200 if bold else 80}:slant={100 if italic else 0}"
    for name in names:
        fam = _GENERIC.get(name.lower(), name)
        got = _fc_match(fam + suffix)
        if got is not None and fam.lower() in got[0] and got[2]:
            return got[2], None
    got = _fc_match(_GENERIC.get(names[0].lower(), names[0]) + suffix)
    if got is not None and got[2]:
        return got[2], names[0]
    for name in names:                   # no fontconfig: font files named like the family
        try:
            return str(find_font(_GENERIC.get(name.lower(), name))), None
        except FormatError:
            continue
    return str(find_font("DejaVu Sans")), names[0]


@functools.lru_cache(maxsize=4096)
def _glyph(file: str, char: str, tol: float):
    """(rings in font units (y up), advance, units per em) of one character."""
    from pathlib import Path

    from insitu.patterns.text import _FlattenPen, _font

    f = _font(Path(file))
    upem = float(f["head"].unitsPerEm)
    cmap = f.getBestCmap() or {}
    name = cmap.get(ord(char)) or ".notdef"
    gs = f.getGlyphSet()
    pen = _FlattenPen(gs, tol * upem)
    if not char.isspace():
        gs[name].draw(pen.pen)
    return tuple(pen.rings), float(f["hmtx"][name][0]), upem


class _Run:
    """Characters to place with their styles and the positions the attributes give."""

    def __init__(self):
        self.chars: list[tuple[str, dict, float | None, float | None, float, float,
                               float | None, object]] = []


def _collect(doc, el, style: dict, run: _Run, vp, skip_space: list, path_el=None) -> None:
    """Append the characters of ``el`` and its tspans to ``run`` (whitespace collapsed)."""
    from insitu.patterns.svg_doc import computed

    if style.get("display") == "none":
        return
    vw, vh = vp
    fp = float(style["font-size"])
    xs = [length(v, vw, fp) for v in (el.get("x") or "").replace(",", " ").split()]
    ys = [length(v, vh, fp) for v in (el.get("y") or "").replace(",", " ").split()]
    dxs = [length(v, vw, fp) for v in (el.get("dx") or "").replace(",", " ").split()]
    dys = [length(v, vh, fp) for v in (el.get("dy") or "").replace(",", " ").split()]
    rot = numbers(el.get("rotate"))
    k = 0

    def add(text: str, sty: dict):
        nonlocal k
        preserve = sty.get("xml:space") == "preserve"
        text = re.sub(r"[\n\r]", "" if not preserve else " ", text or "")
        text = text.replace("\t", " ")
        for ch in text:
            if ch == " " and not preserve and skip_space[0]:
                continue
            skip_space[0] = ch == " "
            run.chars.append((ch, sty, xs[k] if k < len(xs) else None,
                              ys[k] if k < len(ys) else None, dxs[k] if k < len(dxs) else 0.0,
                              dys[k] if k < len(dys) else 0.0,
                              rot[min(k, len(rot) - 1)] if rot else None, path_el))
            k += 1

    add(el.text, style)
    for child in el:
        name = local(child.tag)
        if name in ("tspan", "textPath", "flowSpan", "a"):
            sty = computed(doc.decl.get(child, {}), style)
            sub = doc.ids.get(href(child) or "") if name == "textPath" else path_el
            before = len(run.chars)
            _collect(doc, child, sty, run, vp, skip_space, sub)
            if name == "textPath" and len(run.chars) > before:
                offset = child.get("startOffset", "0")
                first = run.chars[before]
                run.chars[before] = (first[0], first[1], 0.0 if "%" in offset else
                                     length(offset, 0, float(sty["font-size"])), *first[3:])
            for i in range(before, len(run.chars)):   # the parent's lists, by character
                v = list(run.chars[i])
                for slot, values in ((2, xs), (3, ys)):
                    if v[slot] is None and k < len(values):
                        v[slot] = values[k]
                for slot, values in ((4, dxs), (5, dys)):
                    if k < len(values):
                        v[slot] += values[k]
                run.chars[i] = tuple(v)
                k += 1
        elif name == "tref" or (name and name not in ("title", "desc")):
            doc.skipped[name] += 1
        add(child.tail, style)


def _glyph_region(file, ch, size, tol_user, m):
    rings, adv, upem = _glyph(file, ch, round(tol_user / max(size, 1e-9), 6))
    k = size / upem
    placed = [apply(m, np.column_stack([r[:, 0] * k, -r[:, 1] * k])) for r in rings]
    return placed, adv * k


def _layout(doc, run: _Run, c, path_len) -> list[tuple[list[np.ndarray], dict]]:
    """(glyph rings in page px, style) of every character, anchored per chunk."""
    from insitu.patterns.svg_doc import compose

    out, chunk, pen = [], [], [0.0, 0.0]
    scale = float(np.linalg.norm(c.ctm[:, :2], 2)) or 1.0

    def flush():
        if not chunk:
            return
        anchor = chunk[0][2].get("text-anchor", "start")
        width = chunk[-1][3] - chunk[0][4]
        shift = {"middle": -width / 2, "end": -width}.get(anchor, 0.0)
        for _ch, place, sty, _, _ in chunk:
            out.append((place(shift), sty))
        chunk.clear()

    for ch, sty, x, y, dx, dy, rot, path_el in run.chars:
        if x is not None or y is not None:
            flush()
        if _SHAPED.match(ch):
            doc.effects.setdefault("text in a script that needs shaping",
                                   "outlined letter by letter, unjoined and left to right "
                                   "(convert the text to paths)")
        deco = sty.get("text-decoration", "none")
        if deco not in ("none", "", "normal"):
            doc.effects.setdefault(f"text-decoration {deco}", "not drawn (only the letters)")
        pen[0] = x if x is not None else pen[0]
        pen[1] = y if y is not None else pen[1]
        pen[0] += dx
        pen[1] += dy
        size = float(sty["font-size"])
        bold = sty.get("font-weight", "normal") in ("bold", "bolder") or \
            (sty.get("font-weight", "").isdigit() and int(sty["font-weight"]) >= 550)
        if sty.get("font-variant", "normal") not in ("normal", "none"):
            doc.effects.setdefault(f"font-variant {sty['font-variant']}",
                                   "not drawn: its text is outlined in plain letters")
        italic = sty.get("font-style", "normal") in ("italic", "oblique")
        file, missing = font_for(sty.get("font-family", "sans-serif"), bold, italic)
        if missing:
            doc.fonts.setdefault(missing, file.rsplit("/", 1)[-1])
        _, adv, upem = _glyph(file, ch, 1.0)
        adv = adv * size / upem
        x0, y0 = pen[0], pen[1]
        dy_path = dy if path_el is not None else 0.0
        visible = sty.get("visibility", "visible") == "visible" and not ch.isspace()

        def place(shift, x0=x0, y0=y0, adv=adv, size=size, file=file, ch=ch, rot=rot,
                  path_el=path_el, visible=visible, dy_path=dy_path):
            if not visible:
                return []
            if path_el is not None and path_len is not None:
                where = path_len(path_el, x0 + shift + adv / 2)
                if where is None:
                    return []
                (px, py), ang = where
                ca, sa = math.cos(ang), math.sin(ang)
                m = np.array([[ca, -sa, px - ca * adv / 2 - sa * dy_path],
                              [sa, ca, py - sa * adv / 2 + ca * dy_path]])
            else:
                a = math.radians(rot or 0.0)
                m = np.array([[math.cos(a), -math.sin(a), x0 + shift],
                              [math.sin(a), math.cos(a), y0]])
            return _glyph_region(file, ch, size, doc.tol_px / scale, compose(c.ctm, m))[0]

        chunk.append((ch, place, sty, x0 + adv, x0))
        pen[0] += adv + length(sty.get("letter-spacing", "0"), 0, size) + \
            (length(sty.get("word-spacing", "0"), 0, size) if ch == " " else 0.0)
    flush()
    return out


def _path_length_fn(doc, c):
    """f(path element, distance) → ((x, y), angle) along the path in the text's user space,
    None beyond its ends."""
    from insitu.patterns.svg_doc import matrix
    from insitu.patterns.svg_shapes import geometry, subpaths

    cache = {}

    def at(path_el, s):
        if path_el not in cache:
            import svgelements as se

            shape = geometry(path_el, "path", doc.style_of(path_el), c.viewport)
            subs = subpaths(shape, se, doc.tol_px, doc.budget, doc.describe(path_el)) \
                if shape is not None else []
            pts = apply(matrix(path_el.get("transform")), np.concatenate(
                [q for q, _ in subs])) if subs else np.zeros((0, 2))
            seg = np.linalg.norm(np.diff(pts, axis=0), axis=1) if len(pts) > 1 else np.zeros(0)
            cache[path_el] = (pts, np.concatenate([[0.0], np.cumsum(seg)]))
        pts, cum = cache[path_el]
        if len(pts) < 2 or not 0 <= s <= cum[-1]:
            return None
        i = min(int(np.searchsorted(cum, s, "right")) - 1, len(pts) - 2)
        t = (s - cum[i]) / max(cum[i + 1] - cum[i], 1e-12)
        p = pts[i] + t * (pts[i + 1] - pts[i])
        d = pts[i + 1] - pts[i]
        return (float(p[0]), float(p[1])), math.atan2(d[1], d[0])

    return at


def _flow(doc, el, style: dict, run: _Run, c) -> None:
    """Characters of a <flowRoot>, wrapped in the first rect of its <flowRegion>."""
    from insitu.patterns.svg_doc import computed

    frame = next((r for reg in el if local(reg.tag) == "flowRegion" for r in reg
                  if local(r.tag) == "rect"), None)
    vw, vh = c.viewport
    fx = length(frame.get("x"), vw) if frame is not None else 0.0
    fy = length(frame.get("y"), vh) if frame is not None else 0.0
    fw = length(frame.get("width"), vw) if frame is not None else float("inf")
    y = fy
    for para in el:
        if local(para.tag) not in ("flowPara", "flowDiv"):
            continue
        sty = computed(doc.decl.get(para, {}), style)
        size = float(sty["font-size"])
        lh = sty.get("line-height", "1.25")
        step = length(lh, size, size) if re.search(r"[a-z%]", lh) else float(
            (numbers(lh) or [1.25])[0]) * size
        text = " ".join("".join(para.itertext()).split())
        y += size if y == fy else 0.0
        line, words = "", text.split(" ")
        for word in words + [None]:
            trial = word if not line else f"{line} {word}" if word is not None else line
            file, _ = font_for(sty.get("font-family", "sans-serif"), False, False)
            width = sum(_glyph(file, ch, 1.0)[1] for ch in (trial or "")) * size / \
                _glyph(file, "x", 1.0)[2]
            if word is not None and (width <= fw or not line):
                line = trial
                continue
            for i, ch in enumerate(line):
                run.chars.append((ch, sty, fx if i == 0 else None, y if i == 0 else None,
                                  0.0, 0.0, None, None))
            y += step
            line = word or ""


def text_items(doc, el, name: str, c, style: dict) -> list[Item]:
    """The glyph outlines a <text> or <flowRoot> paints (fill, and stroke at least the beam
    wide), or inside a clipPath their area."""
    run = _Run()
    if name == "flowRoot":
        _flow(doc, el, style, run, c)
        doc.effects.setdefault(doc.describe(el), "flowed text (Inkscape's SVG 1.2; browsers do "
                                                 "not draw it) wrapped in its frame")
    else:
        _collect(doc, el, style, run, c.viewport, [True])
    items = []
    for rings, sty in _layout(doc, run, c, _path_length_fn(doc, c)):
        if not rings:
            continue
        g = region(rings, "nonzero")
        if c.clip:
            items.append(Item(g, 0.0, doc.describe(el)))
            continue
        fill = resolve(sty.get("fill"), sty.get("fill-opacity", 1), sty, doc)
        if not fill.none:
            flat = fill.server is None and fill.alpha >= 1 and not c.why
            items.append(Item(g, fill.lum if flat else None, doc.describe(el),
                              "" if flat else c.why or fill.server or "fill-opacity"))
        stroke = resolve(sty.get("stroke"), sty.get("stroke-opacity", 1), sty, doc)
        w = length(sty.get("stroke-width", "1"), 0, float(sty["font-size"]), 1.0) * \
            math.sqrt(abs(float(np.linalg.det(c.ctm[:, :2]))))
        if not stroke.none and w >= doc.beam_px:
            s = shapely.unary_union([stroke_region(r, w, closed=True) for r in rings])
            items.append(Item(s, stroke.lum if stroke.alpha >= 1 and not c.why else None,
                              doc.describe(el), c.why or "stroke-opacity"))
    return items
