"""DXF files (ezdxf) → :class:`Pattern` in mm, y up: fills where the file has fills.

HATCH, MPOLYGON, SOLID, TRACE, wide (LW)POLYLINEs (banded as ezdxf draws them: each
segment's start and end width) and text (TEXT, ATTRIB, an ATTDEF's tag, MTEXT through ezdxf's
own text-to-path with the file's style and font) are fills: the contours of the region. The
boundary of an associative hatch is not marked again, nor a closed outline that
runs along a fill's edge. Other closed shapes, and chains of open pieces whose ends meet
within ``join_mm``, are outlines — closed lines, marked but not filled — unless ``fill="all"``
(then filled, even-odd: a circle inside a frame is a hole); ``fill="none"`` marks every fill's
edge as an outline instead. A WIPEOUT masks what was drawn before it (as ezdxf's drawing
add-on paints it in the background colour): fills lose its area, lines their part under it
(an outline it cuts is marked as its visible pieces, also with ``fill="all"``); what comes
after it in the file is drawn over it. Units from ``$INSUNITS`` (``units=`` overrides; none:
mm, with ``$MEASUREMENT`` and a warning when the drawing is only a few units across, as a
plan in metres is), said in ``notes``. A file that ezdxf cannot read is read again through
``ezdxf.recover``.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns.model import Pattern, contours_of, region
from insitu.patterns.vector import (TOL_MM, Budget, _check_file, _fail, _non_empty, bezier_steps,
                                    check_extent, check_finite)

FILL_MODES = ("auto", "all", "none")
_FILLS = ("HATCH", "MPOLYGON", "SOLID", "TRACE")
_TEXTS = ("TEXT", "ATTRIB", "MTEXT")
_UNITS = {"in": 1, "ft": 2, "mm": 4, "cm": 5, "m": 6, "um": 13, "yd": 10}


def _chain(pieces: list[np.ndarray], tol: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Join open polylines whose ends meet (within ``tol``) into longer chains.

    Returns (closed loops without repeated end point, open chains). Chains run only through
    points where exactly two ends meet."""
    from scipy.spatial import cKDTree

    if not pieces:
        return [], []
    ends = np.array([[p[0], p[-1]] for p in pieces]).reshape(-1, 2)
    parent = np.arange(len(ends))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in cKDTree(ends).query_pairs(tol):
        parent[find(i)] = find(j)
    node = np.array([find(i) for i in range(len(ends))])
    at: dict[int, list[int]] = {}
    for e, n in enumerate(node):
        at.setdefault(int(n), []).append(e)
    used = np.zeros(len(pieces), bool)

    def walk(end: int) -> list[int]:
        """Ends to traverse, starting after the piece-end ``end`` (piece*2 + side)."""
        seq = []
        while True:
            others = [e for e in at[int(node[end])] if e != end]
            if len(at[int(node[end])]) != 2 or used[others[0] // 2]:
                return seq
            nxt = others[0]
            used[nxt // 2] = True
            seq.append(nxt)
            end = nxt ^ 1

    loops, opens = [], []
    for i in range(len(pieces)):
        if used[i]:
            continue
        used[i] = True
        fwd = walk(2 * i + 1)
        back = walk(2 * i)
        # walking backwards entered each piece at end e, so read forwards it finishes there
        parts = [pieces[e // 2] if e % 2 else pieces[e // 2][::-1] for e in back[::-1]]
        parts.append(pieces[i])
        parts += [pieces[e // 2] if e % 2 == 0 else pieces[e // 2][::-1] for e in fwd]
        pts = np.vstack([parts[0]] + [q[1:] for q in parts[1:]])
        if len(pts) >= 3 and np.linalg.norm(pts[0] - pts[-1]) <= tol:
            loops.append(pts[:-1])
        else:
            opens.append(pts)
    return loops, opens


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
    """(mm per drawing unit, the note saying where it came from)."""
    from ezdxf import units as u

    if units is not None:
        if units not in _UNITS:
            raise FormatError(f"{path}: units={units!r}: expected one of {', '.join(_UNITS)}")
        return float(u.conversion_factor(_UNITS[units], u.MM)), f"units: {units} (given)"
    code = int(doc.header.get("$INSUNITS", 0) or 0)
    if code == 0:
        system = {0: ", $MEASUREMENT imperial", 1: ", $MEASUREMENT metric"}.get(
            doc.header.get("$MEASUREMENT"), "")
        return 1.0, (f"units: none in the file ($INSUNITS unset{system}) → taken as mm "
                     "(;units= to change)")
    try:
        k = float(u.conversion_factor(code, u.MM))
    except Exception:  # noqa: BLE001 — an unknown code
        raise FormatError(f"{path}: $INSUNITS {code} is not a known unit") from None
    return k, f"units: $INSUNITS {code} ({u.unit_name(code)}) → ×{k:g} mm"


def _attdef_text(e, doc):
    """A TEXT of an ATTDEF's tag with its style, place and alignment."""
    from ezdxf.entities import Text

    attrs = {k: v for k, v in e.dxfattribs().items()
             if Text.DXFATTRIBS.get(k) is not None and k not in ("handle", "owner")}
    attrs["text"] = e.dxf.get("tag", "")
    return Text.new(dxfattribs=attrs, doc=doc)


def _entities(doc):
    """Model-space entities, blocks exploded; an ATTDEF as the TEXT of its tag; MTEXT
    exploded into TEXT (its background mask dropped)."""
    from ezdxf import disassemble
    from ezdxf.addons.mtxpl import MTextExplode
    from ezdxf.layouts import VirtualLayout

    for e in disassemble.recursive_decompose(doc.modelspace()):
        if e.dxftype() == "ATTDEF":  # shown as its tag, as ezdxf's drawing add-on does
            yield _attdef_text(e, doc)
            continue
        if e.dxftype() != "MTEXT":
            yield e
            continue
        vl = VirtualLayout()
        with MTextExplode(vl, doc) as x:
            x.explode(e, destroy=False)
        for v in vl:
            if v.dxftype() != "SOLID":
                v.dxf.layer = e.dxf.get("layer", "0")
                yield v


def _width(e) -> float:
    """The drawing width of a wide LWPOLYLINE / 2-D POLYLINE (0: a plain line)."""
    if e.dxftype() == "LWPOLYLINE":
        w = [float(e.dxf.get("const_width", 0) or 0)]
        w += [max(float(p[2]), float(p[3])) for p in e.get_points("xyseb")]
        return max(w)
    if e.dxftype() == "POLYLINE" and e.is_2d_polyline:
        w = [float(e.dxf.get("default_start_width", 0) or 0)]
        w += [max(float(v.dxf.get("start_width", 0)), float(v.dxf.get("end_width", 0)))
              for v in e.vertices]
        return max(w)
    return 0.0


def _flatten(sub, distance: float, budget: Budget, what: str) -> np.ndarray:
    """(n, 2) drawing units: the sub-path ``sub`` flattened within ``distance``; its segments
    (bounded from its control points before flattening) are taken from ``budget``."""
    n, start = 0, sub.start
    for cmd in sub.commands():
        ctrl = getattr(cmd, "ctrl1", None), getattr(cmd, "ctrl2", None), getattr(cmd, "ctrl", None)
        ctrl = [start, *(c for c in ctrl if c is not None), cmd.end]
        n += 1 if len(ctrl) == 2 else 2 * bezier_steps([(c.x, c.y) for c in ctrl], distance) + 4
        start = cmd.end
    budget.take(n, what)
    return np.array([(v.x, v.y) for v in sub.flattening(distance)], np.float64).reshape(-1, 2)


def _check_attributes(e, path: Path, what: str) -> None:
    """FormatError naming the entity and the attribute when a number or point among its DXF
    attributes (centre, radius, angles, ratio, extrusion, ...) is not finite."""
    for key, value in e.dxf.all_existing_dxf_attribs().items():
        if isinstance(value, float) or hasattr(value, "isclose"):        # a float, Vec2 or Vec3
            if not np.isfinite(np.asarray(tuple(value) if hasattr(value, "x") else value,
                                          np.float64)).all():
                raise FormatError(f"{path}: {what}: {key} is not a finite number "
                                  f"({tuple(value) if hasattr(value, 'x') else value})")
    kind = e.dxftype()
    lists = {"SPLINE": lambda: {"control points": e.control_points, "fit points": e.fit_points,
                                "knots": e.knots, "weights": e.weights},
             "LWPOLYLINE": lambda: {"points": e.get_points("xyseb")},
             "POLYLINE": lambda: {"vertices": [v.dxf.location for v in e.vertices]},
             "MESH": lambda: {"vertices": e.vertices}}.get(kind)
    for key, values in (lists() if lists else {}).items():
        a = np.asarray([tuple(v) if hasattr(v, "__len__") else (v,) for v in values], np.float64)
        if not np.isfinite(a).all():
            raise FormatError(f"{path}: {what}: one of its {key} is not a finite number")


def _banded(e, k: float):
    """The area of a wide (LW)POLYLINE as ezdxf's drawing add-on fills it (its TraceBuilder:
    each segment's own start and end width, bulges in 256 chords a turn), shapely, mm."""
    from ezdxf.math import Vec3
    from ezdxf.render import TraceBuilder

    ocs = e.ocs()
    z = float(e.dxf.elevation) if e.dxftype() == "LWPOLYLINE" else Vec3(e.dxf.elevation).z
    polys = []
    for poly in TraceBuilder.from_polyline(e, segments=256).polygons():
        if len(poly) < 3:
            continue
        pts = ocs.points_to_wcs(Vec3(v.x, v.y, z) for v in poly) if ocs.transform else poly
        ring = np.array([(v.x, v.y) for v in pts], np.float64) * k
        polys.append(shapely.make_valid(shapely.Polygon(ring)))
    return shapely.unary_union(polys) if polys else shapely.Polygon()


def _check_radius(e, path: Path) -> None:
    if e.dxftype() in ("CIRCLE", "ARC") and not float(e.dxf.radius) > 0:
        raise FormatError(f"{path}: {e.dxftype()} #{e.dxf.get('handle', '?')} has radius "
                          f"{float(e.dxf.radius):g} (must be > 0)")


def _masked(mask, fills: list, closed: list[np.ndarray], pieces: list[np.ndarray]):
    """What a WIPEOUT polygon ``mask`` (shapely, mm) leaves of the fills, closed outlines and
    open pieces drawn before it: (fills, closed outlines it does not touch, open pieces)."""
    fills = [g.difference(mask) for g in fills]
    keep, cut = [], []
    for r in closed:
        (keep if not mask.intersects(shapely.LinearRing(r)) else cut).append(r)
    lines = [shapely.LineString(np.vstack([r, r[:1]])) for r in cut]
    lines += [shapely.LineString(q) for q in pieces]
    out = [np.asarray(g.coords)[:, :2] for line in lines
           for g in shapely.get_parts(line.difference(mask))
           if g.geom_type == "LineString" and g.length > 0]
    return fills, keep, out


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


def load_dxf(path: str | Path, tol_mm: float = TOL_MM, join_mm: float = 1e-3,
             fill: str = "auto", units: str | None = None) -> Pattern:
    """DXF file → Pattern (mm; model space, blocks exploded, layers that are off or frozen
    and invisible entities skipped): fills and outlines as the module docstring says.
    Curves stay within ``tol_mm`` of the true curve, or within 2e-5 of their entity's size
    when that is looser. ``fill``: auto | all | none; ``units``: in, ft, mm, cm, m, um or yd for a file that lacks
    or misstates ``$INSUNITS``. Bad entities are refused in one line naming them."""
    from ezdxf import path as dxfpath
    from ezdxf.addons import text2path

    path = Path(path)
    _check_file(path)
    logging.getLogger("ezdxf").setLevel(logging.ERROR)  # its repairs are summed up in notes
    if fill not in FILL_MODES:
        raise FormatError(f"{path}: fill={fill!r}: expected one of {', '.join(FILL_MODES)}")
    try:
        doc, note = _read(path)
        k, unit_note = _scale(doc, units, path)
        notes = [unit_note] + ([note] if note else [])
        budget = Budget(path)
        hidden = {layer.dxf.name.lower() for layer in doc.layers
                  if layer.is_off() or layer.is_frozen()}
        fills, edges, closed, pieces, skip = [], [], [], [], set()
        wipeouts = 0
        for e in _entities(doc):
            if e.dxf.get("layer", "0").lower() in hidden or e.dxf.get("invisible", 0):
                continue
            kind = e.dxftype()
            what = f"{kind} #{e.dxf.get('handle', '?')}"
            _check_attributes(e, path, what)
            _check_radius(e, path)
            if kind == "WIPEOUT":
                ring = np.array([(v.x, v.y) for v in e.boundary_path_wcs()]).reshape(-1, 2) * k
                check_extent(ring, path, what)
                if len(ring) >= 3:
                    mask = shapely.make_valid(shapely.Polygon(ring))
                    fills, closed, pieces = _masked(mask, fills, closed, pieces)
                    wipeouts += 1
                continue
            if kind in ("TEXT", "ATTRIB"):
                paths = text2path.make_paths_from_entity(e)
            elif kind in ("HATCH", "MPOLYGON"):
                paths = list(dxfpath.from_hatch(e))
                if e.dxf.get("associative", 0):
                    skip.update(h for bp in e.paths for h in bp.source_boundary_objects)
            else:
                try:
                    paths = [dxfpath.make_path(e)]
                except (TypeError, ValueError):
                    continue  # an entity with no outline (POINT, DIMENSION, IMAGE, ...)
            cv = [np.array([(v.x, v.y, v.z) for v in p.control_vertices()], np.float64)
                  .reshape(-1, 3) for p in paths]
            cv = np.concatenate(cv or [np.zeros((0, 3))])
            check_extent(cv[:, :2] * k, path, what)
            check_finite(cv, path, what)                 # z too, before flattening (nan: no end)
            cv = cv[:, :2] * k
            # within tol_mm, or 2e-5 of the entity's size (a 100 m drawing marked at 50 mm)
            tol = max(tol_mm, 2e-5 * float(np.ptp(cv, axis=0).max())) if len(cv) else tol_mm
            rings, lines = [], []
            for p in paths:
                for sub in p.sub_paths():
                    pts = _flatten(sub, tol / k, budget, what) * k
                    if len(pts) < 2:
                        continue
                    if sub.is_closed or np.linalg.norm(pts[0] - pts[-1]) <= join_mm:
                        if len(pts) >= 4:
                            rings.append(pts[:-1])
                    else:
                        lines.append(pts)
            width = _width(e) * k
            if kind in _FILLS or kind in _TEXTS:
                if rings:
                    fills.append(region(rings, "evenodd"))
                    edges.extend(rings)
            elif width > 0:
                fills.append(_banded(e, k))
            elif e.dxf.get("handle") not in skip:
                closed.extend(rings)
                pieces.extend(lines)
        loops, opens = _chain(pieces, join_mm)
        loops = [r for r in closed + loops if len(r) >= 3]
        contours, outlines, dropped = _combine(shapely.unary_union(fills), edges, loops, fill,
                                      max(10 * join_mm, 1e-2))
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 — any parser failure is a bad file, said in one line
        raise _fail(path, "DXF", e) from e
    if fills:
        notes.append(f"{len(fills)} fill(s) (hatch, solid, wide polyline, text) marked as "
                     "areas" if fill != "none" else "fills marked as outlines (fill=none)")
    if loops:
        notes.append(f"{len(loops)} closed outline(s) " + (
            "filled (fill=all)" if fill == "all" else
            f"marked as lines, {dropped} of them along a fill's edge (not marked again)"))
    if wipeouts:
        notes.append(f"{wipeouts} WIPEOUT(s) mask what was drawn before them")
    paths_out = [np.vstack([r, r[:1]]) for r in outlines] + opens
    small = _small_drawing(contours, paths_out, unit_note)
    if small:
        notes.append(small)
    return _non_empty(Pattern(tuple(contours), tuple(paths_out), path.name,
                              notes=tuple(notes)), path, "drawable entities")


def _combine(filled, fill_rings, outlines: list[np.ndarray], mode: str, tol: float):
    """(contours of the marked region, closed outlines to mark as lines, how many outlines
    were dropped) for ``mode``; an outline that runs along a fill's boundary ring (within
    ``tol`` mm) is dropped."""
    n = len(outlines)
    if mode == "all":
        return contours_of(shapely.unary_union([filled, region(outlines, "evenodd")])), [], 0
    edges = contours_of(filled)
    if fill_rings and outlines:
        rings = [shapely.LinearRing(r) for r in fill_rings]
        tree = shapely.STRtree(rings)
        kept = []
        for r in outlines:
            ring = shapely.LinearRing(r)
            near = tree.query(ring, predicate="dwithin", distance=tol)
            if not any(shapely.hausdorff_distance(ring, rings[i]) <= tol for i in near):
                kept.append(r)
        outlines = kept
    if mode == "none":
        return [], edges + outlines, n - len(outlines)
    return edges, outlines, n - len(outlines)
