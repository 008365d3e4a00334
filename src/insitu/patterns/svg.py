"""SVG files (``.svg``, ``.svgz``) → :class:`Pattern` in mm, y up, painted as a browser
paints them.

The document is walked as a browser renders it (:mod:`insitu.patterns.svg_walk`: CSS,
``<use>``/``<symbol>``, viewports, clip paths as geometry, markers, dashes, text outlined
with its font). Flat opaque paints stay vector: a dark paint adds to the marked region, a
light one erases what was painted before it; a stroke at least ``beam_mm`` wide is its area,
a thinner dark one a line along its centre. Everything else (gradients, patterns, opacity,
masks, filters, images) is marked by what it looks like (:mod:`insitu.patterns.svg_paint`):
cairosvg renders the document over those elements at the beam's resolution, and the render,
clipped to their regions, is thresholded (``paint="threshold"``) or dithered
(``paint="dither"``: dots as scan lines). What lies outside the page (``width`` × ``height``,
or the ``viewBox``) is clipped as a renderer clips it, with a warning.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.formats.limits import MAX_DRAWING_BYTES
from insitu.patterns.model import Pattern, contours_of
from insitu.patterns.svg_doc import computed, length, matrix, read_root, viewbox_matrix, viewbox_of
from insitu.patterns.vector import (
    BEAM_MM,
    MM_PER_PX,
    PAINT_MODES,
    TOL_MM,
    _check_file,
    _fail,
    _non_empty,
)

# svgelements turns mm and cm into px with 0.0393701 in/mm; this ppi makes those exact
_SVG_PPI = 96.0 / (25.4 * 0.0393701)


def _page(root) -> tuple[tuple[float, float] | None, np.ndarray, tuple[float, float]]:
    """(page (w, h) px or None when the file gives neither a size nor a viewBox, the root's
    viewBox matrix, the viewport (w, h) px percentages refer to: without a page, a
    1000 px square whose bottom edge is the pattern's y = 0)."""
    vb = viewbox_of(root)

    def absolute(key):
        v = root.get(key)
        return length(v) if v and "%" not in v and length(v) > 0 else None

    w, h = absolute("width"), absolute("height")
    if vb is not None:
        w = w or (h * vb[2] / vb[3] if h else vb[2])
        h = h or w * vb[3] / vb[2]
        return (w, h), viewbox_matrix(vb, w, h, root.get("preserveAspectRatio")), vb[2:]
    if w or h:           # a missing size is 100 % of svgelements' 1000 px viewport
        return (w or 1000.0, h or 1000.0), matrix(None), (w or 1000.0, h or 1000.0)
    return None, matrix(None), (1000.0, 1000.0)


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


def _units_note(root, page) -> str:
    w, vb = root.get("width"), viewbox_of(root)
    if vb is not None and page is not None:
        return (f"units: width {w or '100%'}, viewBox {vb[2]:g} wide → 1 user unit = "
                f"{page[0] * MM_PER_PX / vb[2]:.6g} mm")
    if w:
        return f"units: width {w}, no viewBox → 1 user unit = 1 px = {MM_PER_PX:.6g} mm"
    return f"units: no width/height → 1 user unit = 1 px (1/96 in) = {MM_PER_PX:.6g} mm"


def _walk(root, path: Path, tol_px: float, beam_px: float):
    """(the Doc with what the walk collected, the items painted)."""
    from insitu.patterns.svg_doc import opacity, url_id
    from insitu.patterns.svg_walk import Ctx, Doc, children

    doc = Doc(root, path, tol_px, beam_px)
    page, ctm, view = _page(root)
    style = computed(doc.decl.get(root, {}), None)
    why = "opacity" if opacity(style.get("opacity", 1)) < 1 else \
        "mask" if url_id(style.get("mask")) else ""
    return doc, page, children(doc, root, Ctx(ctm, style, view, why))


def load_svg(path: str | Path, tol_mm: float = TOL_MM, beam_mm: float = BEAM_MM,
             paint: str = "threshold") -> Pattern:
    """SVG file → Pattern (mm, y up, origin at the document's bottom-left corner): what a
    browser paints dark (see the module docstring). Units come from the document's
    width/height/viewBox (user unit = 1/96 in when there are none); the choice is in
    ``notes``; what is left out or approximated is said there in lines starting with
    "warning:". ``paint``: threshold | dither, how paints that are not flat are marked."""
    from insitu.patterns import svg_paint

    path = Path(path)
    _check_file(path)
    if paint not in PAINT_MODES:
        raise FormatError(f"{path}: paint={paint!r}: expected one of "
                          f"{', '.join(PAINT_MODES)}")
    tol_px, beam_px = tol_mm / MM_PER_PX, beam_mm / MM_PER_PX
    try:
        root = read_root(path, MAX_DRAWING_BYTES * 8)
        doc, page, items = _walk(root, path, tol_px, beam_px)
        dark, thin, raster_region = svg_paint.composite(items, paint)
        raster_lines, warnings, pixel = [], [], None
        if not raster_region.is_empty:
            dark, raster_lines, warnings, pixel = svg_paint.apply_renderer(
                root, page, path, dark, raster_region, items, beam_px, paint)
        # slivers thinner than the tolerance (a fill of a straight path, an erasure's seam)
        parts = shapely.get_parts(dark)
        filled = shapely.unary_union(parts[shapely.area(parts) > 0.5 * tol_px
                                           * shapely.length(parts)])
        had_content = not filled.is_empty or bool(thin) or bool(raster_lines)
        filled, lines, clipped = _clip_to_page(filled, thin + raster_lines, page, tol_px)
        notes = [_units_note(root, page)]
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 — any parser failure is a bad file, said in one line
        raise _fail(path, "SVG", e) from e
    height_px = page[1] if page is not None else 1000.0

    def to_mm(p: np.ndarray) -> np.ndarray:
        return np.column_stack([p[:, 0] * MM_PER_PX, (height_px - p[:, 1]) * MM_PER_PX])

    if doc.stroke_areas:
        notes.append(f"{doc.stroke_areas} stroke(s) ≥ beam {beam_mm:g} mm marked as areas")
    if thin:
        notes.append(f"{len(thin)} stroke line(s) thinner than the beam {beam_mm:g} mm marked "
                     "as lines")
    if clipped:
        notes.append(clipped)
    notes += warnings
    for what, effect in list(doc.effects.items())[:5]:
        notes.append(f"warning: {what}: {effect}")
    for family, used in doc.fonts.items():
        notes.append(f"warning: font {family!r} is not installed: its text is outlined "
                     f"with {used}")
    for kind, n in sorted(doc.skipped.items()):
        notes.append(f"warning: {n} <{kind}> element(s) not marked")
    contours = tuple(to_mm(c) for c in contours_of(filled))
    if not had_content and any(not it.region.is_empty for it in items):
        raise FormatError(f"{path}: nothing it paints is dark enough to mark: every paint is "
                          "lighter than 50 % grey (--paint dither marks light shades as dots)")
    if had_content and not contours and not lines and page is not None:
        w, h = (v * MM_PER_PX for v in page)
        raise FormatError(f"{path}: everything it draws lies outside its page ({w:.4g} × "
                          f"{h:.4g} mm)")
    return _non_empty(Pattern(contours, tuple(to_mm(p) for p in lines), path.name,
                              notes=tuple(notes),
                              stroke_widths=tuple(sorted(doc.widths)), beam_mm=beam_mm,
                              raster_mm=None if pixel is None else pixel * MM_PER_PX),
                      path, "filled or stroked shapes")
