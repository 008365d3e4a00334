"""Vector sources: SVG (svgelements) and DXF (ezdxf) files → :class:`Pattern` in mm, y up.

Curves are flattened to polylines that stay within ``tol_mm`` of the true curve (default
0.002 mm, far below a 40 µm laser line). Any failure to read a file is one FormatError.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns.model import Pattern, contours_of, region

TOL_MM = 0.002
MM_PER_PX = 25.4 / 96.0  # CSS pixel, the SVG user unit
# svgelements turns mm and cm into px with 0.0393701 in/mm; this ppi makes those exact
# (px, pt and pc do not depend on it; inches are then off by 5e-7)
_SVG_PPI = 96.0 / (25.4 * 0.0393701)
MAX_MM = 1e5      # 100 m: coordinates beyond this are a broken file, not a pattern


def bezier_points(ctrl, tol: float) -> np.ndarray:
    """Points (n+1, 2) along a quadratic (3 control points) or cubic (4) Bézier, from start to
    end inclusive, spaced uniformly in t so the chords stay within ``tol`` of the curve."""
    c = np.asarray(ctrl, np.float64)
    if len(c) == 3:
        m = float(np.linalg.norm(c[0] - 2 * c[1] + c[2])) / 4.0
    else:
        m = 0.75 * max(float(np.linalg.norm(c[0] - 2 * c[1] + c[2])),
                       float(np.linalg.norm(c[1] - 2 * c[2] + c[3])))
    n = max(1, min(10_000, math.ceil(math.sqrt(m / max(tol, 1e-12)))))
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    s = 1.0 - t
    if len(c) == 3:
        return s * s * c[0] + 2 * s * t * c[1] + t * t * c[2]
    return s**3 * c[0] + 3 * s * s * t * c[1] + 3 * s * t * t * c[2] + t**3 * c[3]


def _arc_steps(radius: float, sweep_rad: float, tol: float) -> int:
    """Chords needed for an arc of ``radius`` so the sagitta stays within ``tol`` and within
    2e-4 · radius (small circles keep their area to 3e-4)."""
    if not (radius > 0 and math.isfinite(radius)):
        return max(1, math.ceil(abs(sweep_rad) / (math.pi / 2)))
    step = 2.0 * math.acos(1.0 - min(tol, 2e-4 * radius) / radius)
    return max(1, min(100_000, math.ceil(abs(sweep_rad) / step)))


def _fail(path: Path, kind: str, e: BaseException) -> FormatError:
    msg = " ".join(str(e).split())[:160] or type(e).__name__
    return FormatError(f"{path}: not a readable {kind} file ({msg})")


def _check_file(path: Path) -> None:
    if not path.is_file():
        raise FormatError(f"{path}: no such pattern file")


def _non_empty(p: Pattern, path: Path, what: str) -> Pattern:
    if p.is_empty:
        raise FormatError(f"{path}: no {what} to mark (empty pattern)")
    return p


# --- SVG ---------------------------------------------------------------------------------------

def _svg_subpaths(shape, se, tol_px: float) -> list[tuple[np.ndarray, bool]]:
    """Flatten one svgelements shape (transforms applied) into (points px, closed) subpaths."""
    path = se.Path(shape)
    path.reify()
    out: list[tuple[np.ndarray, bool]] = []
    pts: list = []
    closed = False

    def flush():
        if len(pts) >= 2:
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


def _dark(color) -> bool:
    """True for a painted colour that marks (luminance ≤ 0.5); False for none/light/transparent."""
    if color is None or color.value is None or color.alpha == 0:
        return False
    return (0.299 * color.red + 0.587 * color.green + 0.114 * color.blue) / 255.0 <= 0.5


def load_svg(path: str | Path, tol_mm: float = TOL_MM) -> Pattern:
    """SVG file → Pattern (mm, y up, origin at the document's bottom-left corner).

    Filled shapes become contours: dark fills add to the region and light fills cut out what
    was painted before them (painter's order, each with its fill-rule). Dark strokes become
    paths along their centre line (closed subpaths as closed lines). Units come from the
    document's width/height/viewBox (user unit = 1/96 in when there are none). Text and
    embedded images are ignored (convert text to paths first).
    """
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
        strokes: list[np.ndarray] = []
        for el in svg.elements():
            if not isinstance(el, se.Shape) or el.values.get("visibility") in ("hidden",
                                                                               "collapse"):
                continue
            subs = _svg_subpaths(el, se, tol_px)
            if not subs:
                continue
            if not all(np.isfinite(q).all() and np.abs(q).max() * MM_PER_PX <= MAX_MM
                       for q, _ in subs if len(q)):
                raise FormatError(f"{path}: a <{el.values.get('tag', 'shape')}> reaches beyond "
                                  f"±{MAX_MM:g} mm (or its coordinates are not numbers)")
            if el.fill is not None and el.fill.value is not None and el.fill.alpha != 0:
                rule = "evenodd" if el.values.get("fill-rule") == "evenodd" else "nonzero"
                rings = [p[:-1] if c else p for p, c in subs if len(p) >= 3]
                g = region(rings, rule)
                if _dark(el.fill):
                    dark.append(g)
                else:  # a light fill erases what was painted before it
                    filled = shapely.unary_union([filled, *dark]).difference(g)
                    dark = []
            if _dark(el.stroke):
                strokes.extend(p for p, _ in subs)
        filled = shapely.unary_union([filled, *dark])
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 — any parser failure is a bad file, said in one line
        raise _fail(path, "SVG", e) from e

    def to_mm(p: np.ndarray) -> np.ndarray:
        return np.column_stack([p[:, 0] * MM_PER_PX, (height_px - p[:, 1]) * MM_PER_PX])

    contours = tuple(to_mm(c) for c in contours_of(filled))
    return _non_empty(Pattern(contours, tuple(to_mm(p) for p in strokes), path.name),
                      path, "filled or stroked shapes")


# --- DXF ---------------------------------------------------------------------------------------

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


def load_dxf(path: str | Path, tol_mm: float = TOL_MM, join_mm: float = 1e-3) -> Pattern:
    """DXF file → Pattern (mm via $INSUNITS, unitless = mm; model space, blocks exploded,
    layers that are off or frozen skipped).

    Lines, polylines, arcs, circles, ellipses, splines, hatches and text (TEXT/MTEXT outlines)
    are read. Closed shapes, and chains of open pieces whose ends meet within ``join_mm``,
    become contours (filled regions, even-odd: a circle inside an outline is a hole); what
    stays open becomes paths.
    """
    import ezdxf
    from ezdxf import disassemble, units
    from ezdxf import path as dxfpath
    from ezdxf.addons import text2path

    path = Path(path)
    _check_file(path)
    try:
        doc = ezdxf.readfile(str(path))
        code = int(doc.header.get("$INSUNITS", 0) or 0)
        k = 1.0 if code == 0 else float(units.conversion_factor(code, units.MM))
        hidden = {layer.dxf.name.lower() for layer in doc.layers
                  if layer.is_off() or layer.is_frozen()}
        closed, pieces = [], []
        for e in disassemble.recursive_decompose(doc.modelspace()):
            if e.dxf.get("layer", "0").lower() in hidden:
                continue
            kind = e.dxftype()
            if kind in ("TEXT", "MTEXT", "ATTRIB"):
                paths = text2path.make_paths_from_entity(e)
            else:
                try:
                    paths = [dxfpath.make_path(e)]
                except (TypeError, ValueError):
                    continue  # an entity with no outline (POINT, DIMENSION, ...)
            for p in paths:
                cv = np.array([(v.x, v.y) for v in p.control_vertices()], np.float64) * k
                if len(cv) and not (np.isfinite(cv).all() and np.abs(cv).max() <= MAX_MM):
                    raise FormatError(f"{path}: a {kind} entity reaches beyond ±{MAX_MM:g} mm "
                                      "(or its coordinates are not numbers)")
                for sub in p.sub_paths():
                    pts = np.array([(v.x, v.y) for v in sub.flattening(tol_mm / k)]) * k
                    if len(pts) < 2:
                        continue
                    if sub.is_closed or np.linalg.norm(pts[0] - pts[-1]) <= join_mm:
                        if len(pts) >= 4:
                            closed.append(pts[:-1])
                    else:
                        pieces.append(pts)
        loops, opens = _chain(pieces, join_mm)
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 — any parser failure is a bad file, said in one line
        raise _fail(path, "DXF", e) from e
    return _non_empty(Pattern(tuple(closed + loops), tuple(opens), path.name),
                      path, "drawable entities")
