"""An SVG document as a browser reads it: the XML (``.svgz`` unzipped), the CSS cascade
(presentation attributes < ``<style>`` rules by specificity < ``style=""`` < ``!important``),
computed styles with inheritance, lengths in CSS px, paints and viewBox transforms.

Matrices are (2, 3) float64 ``[[a, c, e], [b, d, f]]`` mapping user space to page px.
"""

from __future__ import annotations

import gzip
import math
import re
from pathlib import Path

import numpy as np

from insitu.errors import FormatError

SVG_NS = "http://www.w3.org/2000/svg"
XLINK_HREF = "{http://www.w3.org/1999/xlink}href"
# CSS px per unit (mm and cm exact at 96 px per inch)
_UNIT_PX = {"px": 1.0, "": 1.0, "in": 96.0, "cm": 96.0 / 2.54, "mm": 96.0 / 25.4, "pt": 4.0 / 3,
            "pc": 16.0, "q": 96.0 / 101.6}
INHERITED = {
    "fill", "fill-rule", "fill-opacity", "stroke", "stroke-width", "stroke-linecap",
    "stroke-linejoin", "stroke-miterlimit", "stroke-dasharray", "stroke-dashoffset",
    "stroke-opacity", "visibility", "font-family", "font-size", "font-weight", "font-style",
    "font-stretch", "text-anchor", "letter-spacing", "word-spacing", "clip-rule", "color",
    "marker-start", "marker-mid", "marker-end", "direction", "writing-mode", "xml:space",
    "vector-effect", "dominant-baseline", "text-decoration", "font-variant"}
NOT_INHERITED = {"opacity", "display", "clip-path", "mask", "filter", "overflow", "stop-color",
                 "stop-opacity", "transform", "baseline-shift"}
PROPERTIES = INHERITED | NOT_INHERITED | {"font", "marker"}
INITIAL = {"fill": "black", "stroke": "none", "stroke-width": "1", "fill-rule": "nonzero",
           "clip-rule": "nonzero", "font-size": "16", "font-family": "sans-serif",
           "color": "black", "visibility": "visible", "stroke-linecap": "butt",
           "stroke-linejoin": "miter", "stroke-miterlimit": "4"}
_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z%]*)\s*$")
_FONT_SIZES = {"xx-small": 9, "x-small": 10, "small": 13, "medium": 16, "large": 18,
               "x-large": 24, "xx-large": 32}


def local(tag) -> str | None:
    """An element's local name when it is in the SVG namespace (or none), else None."""
    if not isinstance(tag, str):
        return None
    if tag.startswith("{"):
        ns, _, name = tag[1:].partition("}")
        return name if ns == SVG_NS else None
    return tag


def read_root(path: Path, max_bytes: int):
    """The document's root element (``.svgz`` and gzipped files unzipped, at most
    ``max_bytes`` once unzipped). Internal DTD entities (Illustrator's ``&ns_svg;``) are
    expanded — expat bounds their growth —, external ones never fetched."""
    import io
    from xml.etree import ElementTree

    data = path.read_bytes()
    if data[:2] == b"\x1f\x8b":
        with gzip.GzipFile(fileobj=io.BytesIO(data)) as f:
            data = f.read(max_bytes + 1)
        if len(data) > max_bytes:
            raise FormatError(f"{path}: unzips to more than {max_bytes:,} bytes (refused)")
    return ElementTree.fromstring(data)


def _declarations(text: str) -> tuple[list, list]:
    import tinycss2

    normal, important = [], []
    for d in tinycss2.parse_declaration_list(text, skip_comments=True, skip_whitespace=True):
        if d.type == "declaration":
            (important if d.important else normal).append(
                (d.lower_name, tinycss2.serialize(d.value).strip()))
    return normal, important


def cascade(root) -> dict:
    """element → {property: specified value} after the CSS cascade."""
    import cssselect2
    import tinycss2

    xml_space = "{http://www.w3.org/XML/1998/namespace}space"
    out = {el: {("xml:space" if k == xml_space else local(k)): v for k, v in el.attrib.items()
                if (local(k) or "") in PROPERTIES or k == xml_space}
           for el in root.iter()}
    normal, important = cssselect2.Matcher(), cssselect2.Matcher()
    sheets = [el.text for el in root.iter() if local(el.tag) == "style" and el.text]
    for text in sheets:
        for rule in tinycss2.parse_stylesheet(text, skip_comments=True, skip_whitespace=True):
            if rule.type != "qualified-rule":
                continue
            n, i = _declarations(rule.content)
            try:
                selectors = cssselect2.compile_selector_list(rule.prelude)
            except cssselect2.SelectorError:
                continue
            for sel in selectors:
                if sel.pseudo_element is None and not sel.never_matches:
                    if n:
                        normal.add_selector(sel, n)
                    if i:
                        important.add_selector(sel, i)
    wrapper = cssselect2.ElementWrapper.from_xml_root(root)
    for w in wrapper.iter_subtree():
        el, d = w.etree_element, out[w.etree_element]
        if sheets:
            for match in sorted(normal.match(w), key=lambda m: (m[0], m[1])):
                d.update(match[3])
        style = el.get("style")
        if style:
            n, i = _declarations(style)
            d.update(n)
            d.update(i)
        if sheets:
            for match in sorted(important.match(w), key=lambda m: (m[0], m[1])):
                d.update(match[3])
        if "marker" in d:
            for k in ("marker-start", "marker-mid", "marker-end"):
                d.setdefault(k, d["marker"])
    return out


def length(value, ref: float = 0.0, font_px: float = 16.0, default: float = 0.0) -> float:
    """A length in CSS px: numbers, px, mm, cm, in, pt, pc, em, ex and % of ``ref``."""
    if value is None:
        return default
    m = _LENGTH.match(str(value))
    if not m:
        return default
    v, unit = float(m[1]), m[2].lower()
    if unit == "%":
        return v * ref / 100.0
    if unit == "em":
        return v * font_px
    if unit == "ex":
        return v * font_px / 2.0
    return v * _UNIT_PX[unit] if unit in _UNIT_PX else default


def numbers(value) -> list[float]:
    """The numbers of a list attribute ("1, 2 3")."""
    return [float(x) for x in re.findall(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?",
                                         value or "")]


def computed(decl: dict, parent: dict | None) -> dict:
    """The computed style of an element from its specified ``decl`` and its parent's computed
    style; ``font-size`` resolved to px."""
    base = dict(INITIAL) if parent is None else {k: v for k, v in parent.items()
                                                 if k in INHERITED}
    out = dict(base)
    for k, v in decl.items():
        if v == "inherit":
            if parent is not None and k in parent:
                out[k] = parent[k]
        else:
            out[k] = v
    pf = float(parent["font-size"]) if parent is not None else 16.0
    fs = str(decl.get("font-size", "inherit")).strip()
    out["font-size"] = str(pf if fs == "inherit" else _FONT_SIZES.get(fs)
                           or length(fs, pf, pf, pf))
    if "font" in decl:  # the shorthand: its size and family
        m = re.search(r"([\d.]+(?:px|pt|em|%)?)\s*(?:/\S+)?\s+(.+)$", decl["font"])
        if m:
            out["font-size"], out["font-family"] = str(length(m[1], pf, pf, pf)), m[2]
    return out


def matrix(transform: str | None) -> np.ndarray:
    """A ``transform`` attribute as a (2, 3) matrix (identity when absent)."""
    if not transform:
        return np.array([[1.0, 0, 0], [0, 1.0, 0]])
    import svgelements as se

    m = se.Matrix(transform)
    return np.array([[m.a, m.c, m.e], [m.b, m.d, m.f]], np.float64)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ∘ b: apply b, then a. A product beyond float range is inf (no warning): the shapes'
    coordinates are then refused as not finite, naming the element."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.column_stack([a[:, :2] @ b[:, :2], a[:, :2] @ b[:, 2] + a[:, 2]])


def translate(x: float, y: float) -> np.ndarray:
    return np.array([[1.0, 0, x], [0, 1.0, y]])


def viewbox_matrix(viewbox, width: float, height: float, par: str | None) -> np.ndarray:
    """The map of a ``viewBox`` (x, y, w, h) into a viewport ``width`` × ``height`` under
    ``preserveAspectRatio`` (default xMidYMid meet)."""
    vx, vy, vw, vh = viewbox
    if not (vw > 0 and vh > 0):
        return translate(0, 0)
    words = (par or "xMidYMid meet").replace("defer", "").split()
    align = words[0] if words else "xMidYMid"
    sx, sy = width / vw, height / vh
    if align == "none":
        return np.array([[sx, 0, -vx * sx], [0, sy, -vy * sy]])
    s = max(sx, sy) if len(words) > 1 and words[1] == "slice" else min(sx, sy)
    place = {"Min": 0.0, "Mid": 0.5, "Max": 1.0}
    ax, ay = place.get(align[1:4], 0.5), place.get(align[5:8], 0.5)
    return np.array([[s, 0, -vx * s + ax * (width - vw * s)],
                     [0, s, -vy * s + ay * (height - vh * s)]])


def viewbox_of(el):
    """(x, y, w, h) of an element's ``viewBox``, None when it has none (or a bad one)."""
    v = numbers(el.get("viewBox"))
    return tuple(v) if len(v) == 4 and v[2] > 0 and v[3] > 0 else None


def href(el) -> str | None:
    """The id an ``href`` / ``xlink:href`` points to within the document (None otherwise)."""
    h = el.get("href") or el.get(XLINK_HREF) or ""
    return h[1:] if h.startswith("#") else None


def url_id(value: str | None) -> str | None:
    """The id of ``url(#id)`` (clip-path, mask, marker, paint), None for none/other."""
    m = re.match(r"\s*url\(\s*['\"]?#([^)'\"]+)['\"]?\s*\)", value or "")
    return m[1] if m else None


def opacity(value, default: float = 1.0) -> float:
    """An opacity value (number or %) clamped to 0–1."""
    try:
        v = str(value).strip()
        x = float(v[:-1]) / 100 if v.endswith("%") else float(v)
    except (TypeError, ValueError):
        return default
    return min(1.0, max(0.0, x)) if math.isfinite(x) else default
