"""DXF files (ezdxf) → :class:`Pattern` in mm, y up: what a CAD program shows, fills where the
file has fills.

What is drawn: model space with blocks and dimensions exploded, entities on layers that are off,
frozen or not plotted left out (:mod:`insitu.patterns.dxf_walk`). HATCH, MPOLYGON, SOLID, TRACE,
wide (LW)POLYLINEs (banded as ezdxf draws them: each segment's start and end width) and text (TEXT,
ATTRIB, an ATTDEF's tag, MTEXT: the glyphs ezdxf's drawing add-on fills, with the file's styles,
fonts and MTEXT layout) are fills: the contours of the region. A hatch with a pattern (ANSI31,
honeycomb, …) is its pattern's lines, as ezdxf's hatching draws them. The boundary of an associative
solid hatch is not marked again, nor a closed outline that runs along a fill's edge. Lines with a
dashed linetype (the entity's, its layer's or its block's, scaled by $LTSCALE and its own ltscale)
are marked as their dashes. Other closed shapes, and chains of open pieces whose ends meet within
``join_mm``, are outlines — closed lines, marked but not filled — unless ``fill="all"`` (then
filled, even-odd: a circle inside a frame is a hole); ``fill="none"`` marks every fill's edge as an
outline instead. A WIPEOUT masks what was drawn before it (as ezdxf's drawing add-on paints it in
the background colour). Units from a ``$INSUNITS`` the file's header holds (``units=`` overrides;
none: mm, with ``$MEASUREMENT`` and a warning when the drawing is only a few units across, as a plan
in metres is), said in ``notes``. An entity that cannot be drawn (malformed) is skipped and named in
a warning; IMAGEs are named in a warning (not marked); a file of 3-D meshes only is refused saying
so. A file that ezdxf cannot read is read again through ``ezdxf.recover``.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns import dxf_geometry as geo
from insitu.patterns.dxf_walk import (
    MESHES,
    header_has,
    hidden_layers,
    kind_of,
    line_pattern,
    name_of,
    visible_entities,
)
from insitu.patterns.model import Pattern, region
from insitu.patterns.vector import (
    TOL_MM,
    Budget,
    _check_file,
    _fail,
    _non_empty,
    check_extent,
    check_finite,
    dashed,
)

FILL_MODES = ("auto", "all", "none")
_FILLS = ("HATCH", "MPOLYGON", "SOLID", "TRACE")
_TEXTS = ("TEXT", "ATTRIB", "MTEXT")
_PICTURES = ("IMAGE", "OLE2FRAME", "PDFUNDERLAY", "DWFUNDERLAY", "DGNUNDERLAY")
_UNITS = {"in": 1, "ft": 2, "mm": 4, "cm": 5, "m": 6, "um": 13, "yd": 10}


def _read(path: Path):
    """(document, note or None): ezdxf.readfile, else ezdxf.recover (old or damaged files)."""
    import ezdxf
    from ezdxf import recover

    try:
        return ezdxf.readfile(str(path)), None
    except Exception:  # noqa: BLE001 — try the tolerant reader before giving up
        doc, auditor = recover.readfile(str(path))
        if auditor.has_errors:
            raise FormatError(f"{path}: not a readable DXF file ({len(auditor.errors)} "
                              "unrecoverable errors)") from None
        return doc, f"read with ezdxf.recover ({len(auditor.fixes)} fixes)"


def _scale(doc, units: str | None, path: Path) -> tuple[float, str]:
    """(mm per drawing unit, the note saying where it came from): ``units`` if given, else a
    ``$INSUNITS`` the file's own header holds, else mm with a note."""
    from ezdxf import units as u

    if units is not None:
        if units not in _UNITS:
            raise FormatError(f"{path}: units={units!r}: expected one of {', '.join(_UNITS)}")
        return float(u.conversion_factor(_UNITS[units], u.MM)), f"units: {units} (given)"
    code = int(doc.header.get("$INSUNITS", 0) or 0) if header_has(path, b"$INSUNITS") else 0
    if code == 0:
        system = {0: ", $MEASUREMENT imperial", 1: ", $MEASUREMENT metric"}.get(
            doc.header.get("$MEASUREMENT") if header_has(path, b"$MEASUREMENT") else None, "")
        return 1.0, (f"units: none in the file ($INSUNITS unset{system}) → taken as mm "
                     "(;units= to change)")
    try:
        k = float(u.conversion_factor(code, u.MM))
    except Exception:  # noqa: BLE001 — an unknown code
        raise FormatError(f"{path}: $INSUNITS {code} is not a known unit") from None
    return k, f"units: $INSUNITS {code} ({u.unit_name(code)}) → ×{k:g} mm"


def _entities(doc, hidden, skipped, hidden_count):
    """(entity, layer, linetype) of what is drawn (:func:`dxf_walk.visible_entities`); an
    ATTDEF as the TEXT of its tag."""
    for e, layer, ltype in visible_entities(doc, hidden, skipped, hidden_count):
        if e.dxftype() == "ATTDEF":  # shown as its tag, as ezdxf's drawing add-on does
            yield geo.attdef_text(e, doc), layer, ltype
        else:
            yield e, layer, ltype


def _small_drawing(contours, paths, note: str) -> str | None:
    """A warning when a drawing without units (so read as mm) is under 10 units across (a
    plan drawn in metres, a part in inches), None otherwise."""
    if not note.startswith("units: none") or not (contours or paths):
        return None
    w, h = np.ptp(np.concatenate([*contours, *paths]), axis=0)
    if max(w, h) >= 10:
        return None
    return (f"warning: no units in the file and the drawing is only {w:.4g} × {h:.4g} units: "
            f"marked {w:.4g} × {h:.4g} mm; a plan drawn in metres needs ;units=m "
            "(inches: ;units=in)")


class _Drawing:
    """What the entities add up to, in mm: fills (shapely) and their edge rings, closed
    outlines, open pieces (chained later), lines marked as they are (dashes, hatch pattern
    lines), and counts for the notes."""

    def __init__(self) -> None:
        self.fills: list = []
        self.edges: list[np.ndarray] = []
        self.closed: list[np.ndarray] = []
        self.pieces: list[np.ndarray] = []
        self.lines: list[np.ndarray] = []
        self.skip: set[str] = set()
        self.notes: list[str] = []
        self.wipeouts = self.patterns = self.dashed = 0
        self.context = None             # ezdxf's drawing add-on's, for text


def _text_paths(d: _Drawing, doc, e) -> list:
    """The glyph outlines of a TEXT, ATTRIB or MTEXT as ezdxf's drawing add-on fills them
    (its fonts, MTEXT layout and inline formatting), ezdxf paths."""
    from ezdxf.addons.drawing import Frontend, RenderContext
    from ezdxf.addons.drawing.recorder import FilledPathsRecord, Recorder

    if d.context is None:
        d.context = RenderContext(doc)
    recorder = Recorder()
    Frontend(d.context, recorder).draw_entities([e])
    return [p.to_path() for r, _ in recorder.player().recordings()
            if isinstance(r, FilledPathsRecord) for p in r.paths]


def _paths(d: _Drawing, doc, e, kind: str) -> list:
    """ezdxf paths of an entity's outline(s); none for an entity without one (POINT, …)."""
    from ezdxf import path as dxfpath

    if kind in _TEXTS:
        return _text_paths(d, doc, e)
    if kind in ("HATCH", "MPOLYGON"):
        return list(dxfpath.from_hatch(e))
    try:
        return [dxfpath.make_path(e)]
    except (TypeError, ValueError):
        return []


def _pattern_lines(d: _Drawing, e, k: float, budget: Budget) -> list[np.ndarray] | None:
    """The pattern lines ((2, 2) mm each) of a hatch with a pattern, as ezdxf's hatching draws
    them; None for a solid one (or a pattern too dense to draw: filled, with a note)."""
    from ezdxf.render import hatching

    if e.dxf.get("solid_fill", 1) or e.pattern is None or not e.pattern.lines:
        return None
    try:
        segs = [(a, b) for a, b in hatching.hatch_entity(e) if not a.isclose(b)]
    except hatching.HatchingError:
        d.notes.append(f"warning: {name_of(e)}'s pattern is too dense to draw: filled solid")
        return None
    budget.take(len(segs), name_of(e))
    return [np.array([[a.x, a.y], [b.x, b.y]]) * k for a, b in segs]


def _add(d: _Drawing, e, kind: str, doc, layer: str, ltype: str, k: float, tol_mm: float,
         join_mm: float, budget: Budget, path: Path) -> None:
    """Add one entity's geometry to ``d`` (geo.Malformed when it cannot be drawn)."""
    what = name_of(e)
    geo.check_attributes(e)
    geo.check_radius(e)
    if kind == "WIPEOUT":
        ring = np.array([(v.x, v.y) for v in e.boundary_path_wcs()]).reshape(-1, 2) * k
        check_extent(ring, path, what)
        if len(ring) >= 3:
            mask = shapely.make_valid(shapely.Polygon(ring))
            d.fills, d.closed, d.pieces = geo.masked(mask, d.fills, d.closed, d.pieces)
            d.wipeouts += 1
        return
    if kind in ("HATCH", "MPOLYGON"):
        lines = _pattern_lines(d, e, k, budget)
        if lines is not None:
            check_extent(np.concatenate(lines) if lines else np.zeros((0, 2)), path, what)
            d.lines += lines
            d.patterns += 1
            return
        if e.dxf.get("associative", 0):
            d.skip.update(h for bp in e.paths for h in bp.source_boundary_objects)
    paths = _paths(d, doc, e, kind)
    cv = [np.array([(v.x, v.y, v.z) for v in p.control_vertices()], np.float64)
          .reshape(-1, 3) for p in paths]
    cv = np.concatenate(cv or [np.zeros((0, 3))])
    check_extent(cv[:, :2] * k, path, what)
    try:
        check_finite(cv, path, what)                 # z too, before flattening (nan: no end)
    except FormatError as err:
        raise geo.Malformed("a coordinate is not a finite number") from err
    cv = cv[:, :2] * k
    # within tol_mm, or 2e-5 of the entity's size (a 100 m drawing marked at 50 mm)
    tol = max(tol_mm, 2e-5 * float(np.ptp(cv, axis=0).max())) if len(cv) else tol_mm
    rings, lines = [], []
    for p in paths:
        for sub in p.sub_paths():
            pts = geo.flatten(sub, tol / k, budget, what) * k
            if len(pts) < 2:
                continue
            if sub.is_closed or np.linalg.norm(pts[0] - pts[-1]) <= join_mm:
                if len(pts) >= 4:
                    rings.append(pts[:-1])
            else:
                lines.append(pts)
    width = geo.width(e) * k
    if kind in _FILLS or kind in _TEXTS:
        if rings:
            d.fills.append(region(rings, "evenodd"))
            d.edges.extend(rings)
    elif width > 0:
        d.fills.append(geo.banded(e, k))
    elif e.dxf.get("handle") not in d.skip:
        pattern = line_pattern(doc, e, layer, ltype)
        if pattern is None:
            d.closed.extend(rings)
            d.pieces.extend(lines)
        elif rings or lines:
            dashes = [x * k for x in pattern]
            d.lines += [q for r in rings for q in dashed(r, dashes, closed=True)]
            d.lines += [q for q in lines for q in dashed(q, dashes)]
            d.dashed += 1


def _summary(d: _Drawing, fill: str, loops, dropped: int, skipped: list[str],
             hidden_count: dict[str, int], hidden: dict[str, str], pictures: dict[str, int],
             meshes: dict[str, int]) -> list[str]:
    """The notes saying what became what and what was left out."""
    notes = []
    if d.fills:
        notes.append(f"{len(d.fills)} fill(s) (hatch, solid, wide polyline, text) marked as "
                     "areas" if fill != "none" else "fills marked as outlines (fill=none)")
    if loops:
        notes.append(f"{len(loops)} closed outline(s) " + (
            "filled (fill=all)" if fill == "all" else
            f"marked as lines, {dropped} of them along a fill's edge (not marked again)"))
    if d.patterns:
        notes.append(f"{d.patterns} pattern hatch(es) marked as their pattern lines")
    if d.dashed:
        notes.append(f"{d.dashed} line(s) marked as the dashes of their linetype")
    if d.wipeouts:
        notes.append(f"{d.wipeouts} WIPEOUT(s) mask what was drawn before them")
    if hidden_count:
        names = sorted(hidden_count, key=hidden_count.get, reverse=True)
        notes.append(f"{sum(hidden_count.values())} entities on layers that are off, frozen "
                     "or not plotted left out (" + ", ".join(
                         f"{n}: {hidden[n.lower()]}" for n in names[:3])
                     + (", …" if len(names) > 3 else "") + ")")
    for kind, n in {**pictures, **meshes}.items():
        what = "raster picture" if kind in _PICTURES else "3-D mesh or solid"
        notes.append(f"warning: {n} {kind} ({what}) not marked")
    if skipped:
        notes.append(f"warning: {len(skipped)} malformed entit{'y' if len(skipped) == 1 else 'ies'}"
                     f" skipped: {skipped[0]}" + (f"; and {len(skipped) - 1} more"
                                                  if len(skipped) > 1 else ""))
    return d.notes + notes


def load_dxf(path: str | Path, tol_mm: float = TOL_MM, join_mm: float = 1e-3,
             fill: str = "auto", units: str | None = None) -> Pattern:
    """DXF file → Pattern (mm; what a CAD program draws of model space): fills, lines and
    outlines as the module docstring says. Curves stay within ``tol_mm`` of the true curve,
    or within 2e-5 of their entity's size when that is looser. ``fill``: auto | all | none;
    ``units``: in, ft, mm, cm, m, um or yd for a file that lacks or misstates ``$INSUNITS``.
    Entities beyond the size limits are refused in one line naming them."""
    path = Path(path)
    _check_file(path)
    logging.getLogger("ezdxf").setLevel(logging.ERROR)  # its repairs are summed up in notes
    if fill not in FILL_MODES:
        raise FormatError(f"{path}: fill={fill!r}: expected one of {', '.join(FILL_MODES)}")
    try:
        doc, note = _read(path)
        k, unit_note = _scale(doc, units, path)
        budget, d, hidden = Budget(path), _Drawing(), hidden_layers(doc)
        skipped, hidden_count, pictures, meshes = [], {}, {}, {}
        for e, layer, ltype in _entities(doc, hidden, skipped, hidden_count):
            kind = kind_of(e)
            if kind in MESHES or kind in _PICTURES:
                seen = meshes if kind in MESHES else pictures
                seen[kind] = seen.get(kind, 0) + 1
                continue
            try:
                _add(d, e, kind, doc, layer, ltype, k, tol_mm, join_mm, budget, path)
            except FormatError:
                raise
            except Exception as err:  # noqa: BLE001 — one malformed entity, named, skipped
                skipped.append(f"{name_of(e)} {' '.join(str(err).split())[:80]}".rstrip())
        loops, opens = geo.chain(d.pieces, join_mm)
        loops = [r for r in d.closed + loops if len(r) >= 3]
        contours, outlines, dropped = geo.combine(shapely.unary_union(d.fills), d.edges, loops,
                                                  fill, max(10 * join_mm, 1e-2))
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 — any parser failure is a bad file, said in one line
        raise _fail(path, "DXF", e) from e
    notes = [unit_note] + ([note] if note else [])
    notes += _summary(d, fill, loops, dropped, skipped, hidden_count, hidden, pictures, meshes)
    paths_out = [np.vstack([r, r[:1]]) for r in outlines] + opens + d.lines
    small = _small_drawing(contours, paths_out, unit_note)
    if small:
        notes.append(small)
    p = Pattern(tuple(contours), tuple(paths_out), path.name, notes=tuple(notes))
    if p.is_empty and meshes:
        raise FormatError(f"{path}: holds only 3-D geometry (" + ", ".join(
            f"{kind} ×{n}" for kind, n in meshes.items()) + "): nothing 2-D to mark (export a "
            "2-D view or section as lines)")
    if p.is_empty and skipped:
        raise FormatError(f"{path}: no drawable entities (malformed, skipped: {skipped[0]})")
    return _non_empty(p, path, "drawable entities")
