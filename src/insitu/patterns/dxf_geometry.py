"""The geometry of DXF entities for :mod:`insitu.patterns.dxf`: open pieces chained into
outlines, wide polylines banded as ezdxf draws them, WIPEOUT masks, fills combined with
outlines, entity checks (a malformed entity raises :class:`Malformed`, which the loader turns
into a note naming it)."""

from __future__ import annotations

import numpy as np
import shapely

from insitu.patterns.model import contours_of, region
from insitu.patterns.vector import Budget, bezier_steps


class Malformed(Exception):
    """An entity that cannot be drawn as it is (a radius of 0, a coordinate that is not a
    number): skipped, and named in a note."""


def chain(pieces: list[np.ndarray], tol: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Join open polylines whose ends meet (within ``tol``) into longer chains.

    Returns (closed loops without repeated end point, open chains). Chains run only through
    points where exactly two ends meet."""
    if not pieces:
        return [], []
    from scipy.spatial import cKDTree

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


def width(e) -> float:
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


def check_attributes(e) -> None:
    """Malformed, naming the attribute, when a number or point among its DXF
    attributes (centre, radius, angles, ratio, extrusion, ...) is not finite."""
    for key, value in e.dxf.all_existing_dxf_attribs().items():
        if isinstance(value, float) or hasattr(value, "isclose"):        # a float, Vec2 or Vec3
            if not np.isfinite(np.asarray(tuple(value) if hasattr(value, "x") else value,
                                          np.float64)).all():
                raise Malformed(f"{key} is not a finite number "
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
            raise Malformed(f"one of its {key} is not a finite number")


def banded(e, k: float):
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


def check_radius(e) -> None:
    """Malformed for a CIRCLE or ARC whose radius is not > 0."""
    if e.dxftype() in ("CIRCLE", "ARC") and not float(e.dxf.radius) > 0:
        raise Malformed(f"has radius {float(e.dxf.radius):g} (must be > 0)")


def masked(mask, fills: list, closed: list[np.ndarray], pieces: list[np.ndarray]):
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


def combine(filled, fill_rings, outlines: list[np.ndarray], mode: str, tol: float):
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


def flatten(sub, distance: float, budget: Budget, what: str) -> np.ndarray:
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


def attdef_text(e, doc):
    """A TEXT of an ATTDEF's tag with its style, place and alignment."""
    from ezdxf.entities import Text

    attrs = {k: v for k, v in e.dxfattribs().items()
             if Text.DXFATTRIBS.get(k) is not None and k not in ("handle", "owner")}
    attrs["text"] = e.dxf.get("tag", "")
    return Text.new(dxfattribs=attrs, doc=doc)
