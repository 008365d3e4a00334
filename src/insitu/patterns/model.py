"""The one pattern model: closed contours (filled regions, even-odd rule) and open paths, in mm,
pattern frame (x right, y up), plus the conversions to and from shapely regions.

Sources (SVG, DXF, images, text, codes) all produce a :class:`Pattern`; fills and the marking
stage read it. Everything here is a plain value: a Pattern is frozen and its arrays read-only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from insitu.errors import FormatError

_EPS = 1e-12


def _clean(points, closed: bool) -> np.ndarray | None:
    """(N, 2) float64 copy without repeated points (and without the closing point if closed);
    None if too few points remain (3 for a contour, 2 for a path)."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] < 2 or not np.isfinite(p[:, :2]).all():
        return None
    p = p[:, :2]
    if len(p) > 1:
        keep = np.ones(len(p), bool)
        keep[1:] = np.any(np.abs(np.diff(p, axis=0)) > _EPS, axis=1)
        p = p[keep]
    if closed:
        while len(p) > 1 and np.all(np.abs(p[0] - p[-1]) <= _EPS):
            p = p[:-1]
    if len(p) < (3 if closed else 2):
        return None
    p = np.ascontiguousarray(p)
    p.setflags(write=False)
    return p


@dataclass(frozen=True, eq=False)
class Pattern:
    """A pattern to mark, in mm, pattern frame (y up).

    contours: closed outlines, each (N, 2) float64 mm with first != last point; together they
        bound the filled region by the even-odd rule (holes are contours inside contours).
    paths: open polylines, each (N, 2) float64 mm, marked as they are (a path whose first and
        last points coincide is a closed line, marked but not filled).
    name: where it came from (file name, ``text:...``), for messages.
    frame: optional (4, 2) outline of the declared extent (a QR code with its quiet zone, an
        image's full size). It is never marked but counts in :meth:`bounds`, so placement and
        scaling keep the margin.
    code: what a code source encoded (:class:`Code`), None for drawings.
    notes: one-line remarks of the loader (units chosen, what became a fill), for the user.
    stroke_widths: widths (mm, as loaded) of the strokes the loader met; with ``beam_mm`` the
        width at or above which they were loaded as areas (thinner ones are lines), so a
        placement that scales the pattern can tell whether to load it again.
    raster_mm: the pixel (mm, as loaded) of paints marked from a render (gradients and the
        like), None when there are none: a placement that enlarges it beyond the beam loads
        the file again at a finer pixel.
    """

    contours: tuple[np.ndarray, ...] = ()
    paths: tuple[np.ndarray, ...] = ()
    name: str = ""
    frame: np.ndarray | None = field(default=None, repr=False)
    code: Code | None = None
    notes: tuple[str, ...] = ()
    stroke_widths: tuple[float, ...] = ()
    beam_mm: float | None = None
    raster_mm: float | None = None

    def __post_init__(self) -> None:
        cs = tuple(c for c in (_clean(c, True) for c in self.contours) if c is not None)
        ps = tuple(p for p in (_clean(p, False) for p in self.paths) if p is not None)
        object.__setattr__(self, "contours", cs)
        object.__setattr__(self, "paths", ps)
        if self.frame is not None:
            object.__setattr__(self, "frame", _clean(self.frame, True))

    def __repr__(self) -> str:
        return (f"Pattern({self.name!r}, {len(self.contours)} contours, {len(self.paths)} paths, "
                f"bounds={self.bounds() if not self.is_empty else None})")

    @property
    def is_empty(self) -> bool:
        """True when there is nothing to mark (no contour and no path)."""
        return not self.contours and not self.paths

    def _all_points(self) -> np.ndarray:
        parts = [*self.contours, *self.paths]
        if self.frame is not None:
            parts.append(self.frame)
        if not parts or self.is_empty:
            raise FormatError(f"pattern {self.name or '(unnamed)'}: empty (nothing to mark)")
        return np.concatenate(parts)

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) mm of contours, paths and frame. FormatError if empty."""
        p = self._all_points()
        lo, hi = p.min(axis=0), p.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    @property
    def centre(self) -> tuple[float, float]:
        """Centre of the bounding box, mm."""
        x0, y0, x1, y1 = self.bounds()
        return (x0 + x1) / 2.0, (y0 + y1) / 2.0

    @property
    def size(self) -> tuple[float, float]:
        """(width, height) of the bounding box, mm."""
        x0, y0, x1, y1 = self.bounds()
        return x1 - x0, y1 - y0

    def map(self, fn, name: str | None = None) -> Pattern:
        """A new Pattern with ``fn((N, 2)) -> (N, 2)`` applied to every array (code, notes and
        stroke widths kept as they were loaded)."""
        return Pattern(tuple(fn(c) for c in self.contours), tuple(fn(p) for p in self.paths),
                       self.name if name is None else name,
                       None if self.frame is None else fn(self.frame), self.code, self.notes,
                       self.stroke_widths, self.beam_mm, self.raster_mm)

    @property
    def mark_width(self) -> float:
        """The width (mm) that placement scales: a code's symbol without its quiet zone,
        else the bounding box's."""
        w = self.size[0]
        if self.code is not None and self.code.quiet:
            w *= self.code.cols / (self.code.cols + 2 * self.code.quiet)
        return w

    def transformed(self, translate=(0.0, 0.0), rotate_deg: float = 0.0, scale: float = 1.0,
                    mirror_x: bool = False) -> Pattern:
        """Mirror (x → −x), scale, rotate (CCW about +z, degrees), all about the bounding-box
        centre, then translate by ``translate`` (mm). Returns a new Pattern."""
        if not (math.isfinite(scale) and scale > 0):
            raise FormatError(f"pattern {self.name}: scale must be > 0, got {scale}")
        c = np.array(self.centre)
        a = math.radians(rotate_deg)
        ca, sa = math.cos(a), math.sin(a)
        m = np.array([[ca, -sa], [sa, ca]]) * scale
        if mirror_x:
            m = m @ np.diag([-1.0, 1.0])
        t = c + np.asarray(translate, np.float64)
        return self.map(lambda p: (p - c) @ m.T + t)

    def placed(self, at_xy, width_mm: float, rotate_deg: float = 0.0) -> Pattern:
        """Scaled so its (unrotated) :attr:`mark_width` is ``width_mm``, its bbox centre moved
        to ``at_xy``, then rotated CCW by ``rotate_deg`` about that point."""
        w = self.mark_width
        if w <= 0:
            raise FormatError(f"pattern {self.name}: zero width, cannot scale it to {width_mm} mm")
        if not (math.isfinite(width_mm) and width_mm > 0):
            raise FormatError(f"pattern {self.name}: width must be > 0 mm, got {width_mm}")
        c = np.array(self.centre)
        return self.transformed(translate=np.asarray(at_xy, np.float64) - c,
                                rotate_deg=rotate_deg, scale=width_mm / w)

    def to_shapely(self) -> BaseGeometry:
        """The filled region (even-odd over ``contours``) as a valid shapely geometry."""
        return region(self.contours, "evenodd")


@dataclass(frozen=True)
class Code:
    """A code symbol: ``symbology`` (a key of ``codes.SYMBOLOGIES``), the ``text`` it
    encodes, its size in modules without the quiet zone (``cols`` × ``rows``) and the
    ``quiet`` zone, modules on each side (part of the pattern's frame, kept clear)."""

    symbology: str
    text: str
    cols: int
    rows: int
    quiet: int


# --- regions: rings + fill rule <-> shapely ---------------------------------------------------

def _winding(pts: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """Winding number of each point (M, 2) about the closed ring (N, 2)."""
    x0, y0 = ring[:, 0], ring[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    w = np.zeros(len(pts), np.int64)
    for s in range(0, len(pts), 256):
        px, py = pts[s:s + 256, 0:1], pts[s:s + 256, 1:2]
        side = (x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)
        up = (y0 <= py) & (y1 > py) & (side > 0)
        down = (y0 > py) & (y1 <= py) & (side < 0)
        w[s:s + 256] = up.sum(axis=1) - down.sum(axis=1)
    return w


def _signed_area(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _simple_region(rings, polys, rule: str) -> BaseGeometry | None:
    """Fast path when no two rings cross (they nest or are apart): keep the rings across which
    the fill changes, then nest them by containment depth. None if the rings cross."""
    tree = shapely.STRtree(polys)
    a, b = tree.query(polys, predicate="intersects")
    pair = a != b
    a, b = a[pair], b[pair]
    if len(a):
        ok = (shapely.contains_properly(polys[a], polys[b])
              | shapely.contains_properly(polys[b], polys[a])
              | shapely.touches(polys[a], polys[b]))
        if not ok.all():
            return None
    inner, outer = tree.query(polys, predicate="within")
    keep = inner != outer
    inner, outer = inner[keep], outer[keep]
    n = len(rings)
    if rule == "nonzero":
        sign = np.sign([_signed_area(r) for r in rings]).astype(np.int64)
        w_in = sign + np.bincount(inner, weights=sign[outer], minlength=n).astype(np.int64)
        w_out = w_in - sign
        boundary = (w_in != 0) != (w_out != 0)
    else:
        boundary = np.ones(n, bool)
    # depth among kept rings only, and each hole's immediate kept parent
    kd = np.bincount(inner[boundary[outer]], minlength=n)
    shells = {}
    holes: dict[int, list] = {}
    for i in np.flatnonzero(boundary):
        if kd[i] % 2 == 0:
            shells[i] = rings[i]
    for i in np.flatnonzero(boundary):
        if kd[i] % 2 == 1:
            parents = outer[(inner == i) & boundary[outer]]
            parent = parents[np.argmax(kd[parents])]
            holes.setdefault(int(parent), []).append(rings[i])
    out = [shapely.Polygon(s, holes.get(i, [])) for i, s in shells.items()]
    out = [g if g.is_valid else shapely.make_valid(g) for g in out]  # e.g. holes sharing edges
    return shapely.unary_union(out) if out else shapely.Polygon()


def region(rings, rule: str = "evenodd") -> BaseGeometry:
    """The region bounded by closed ``rings`` (each (N, 2) mm) under the SVG fill ``rule``
    ("evenodd" or "nonzero"; ring orientation matters for nonzero) as valid shapely geometry."""
    rings = [np.asarray(r, np.float64) for r in rings if len(r) >= 3]
    if not rings:
        return shapely.Polygon()
    if len(rings) == 1:                  # one simple ring: the same region under either rule
        g = shapely.Polygon(rings[0])
        if g.is_valid:
            return g
    polys = np.array([shapely.Polygon(r) for r in rings], dtype=object)
    if shapely.is_valid(polys).all():
        g = _simple_region(rings, polys, rule)  # noqa: SIM102
        if g is not None:
            return g
    # general case: node every ring, polygonize the faces, keep faces by winding number
    lines = shapely.unary_union([shapely.LineString(np.vstack([r, r[:1]])) for r in rings])
    faces = shapely.get_parts(shapely.polygonize(shapely.get_parts(lines)))
    if not len(faces):
        return shapely.Polygon()
    pts = shapely.get_coordinates(shapely.point_on_surface(faces))
    w = np.zeros(len(faces), np.int64)
    for r in rings:
        w += _winding(pts, r)
    keep = (w % 2 == 1) if rule == "evenodd" else (w != 0)
    return shapely.unary_union(faces[keep]) if keep.any() else shapely.Polygon()


def contours_of(geom: BaseGeometry) -> list[np.ndarray]:
    """Exterior and interior rings of every polygon in ``geom`` as (N, 2) arrays (not closed):
    the even-odd contours of that region."""
    out = []
    for poly in shapely.get_parts(geom):
        if poly.geom_type != "Polygon" or poly.is_empty:
            continue
        for ring in (poly.exterior, *poly.interiors):
            c = np.asarray(ring.coords)[:-1, :2]
            if len(c) >= 3:
                out.append(c)
    return out


def normalised(rings, rule: str = "nonzero") -> list[np.ndarray]:
    """Rings under ``rule`` rewritten as equivalent even-odd contours (what Pattern holds)."""
    rings = [np.asarray(r, np.float64) for r in rings]
    if rule == "evenodd":
        return rings
    return contours_of(region(rings, rule))


def from_shapely(geom: BaseGeometry, name: str = "", paths=()) -> Pattern:
    """A Pattern whose contours bound ``geom`` (polygons; lines in ``geom`` become paths)."""
    lines = [np.asarray(g.coords)[:, :2] for g in shapely.get_parts(geom)
             if g.geom_type in ("LineString", "LinearRing")]
    return Pattern(tuple(contours_of(geom)), tuple(paths) + tuple(lines), name)


def to_svg(pattern: Pattern, stroke_mm: float = 0.1) -> str:
    """An SVG document (mm units, y down as SVG wants) drawing the contours filled (even-odd)
    and the paths stroked — for samples, previews and exports."""
    x0, y0, x1, y1 = pattern.bounds()
    w, h = x1 - x0, y1 - y0

    def d(arr, close):
        pts = " ".join(f"{x - x0:.10g},{y1 - y:.10g}" for x, y in arr)
        return f"M {pts}{' Z' if close else ''}"

    body = []
    if pattern.contours:
        body.append('<path fill="black" fill-rule="evenodd" stroke="none" d="'
                    + " ".join(d(c, True) for c in pattern.contours) + '"/>')
    for p in pattern.paths:
        body.append(f'<path fill="none" stroke="black" stroke-width="{stroke_mm:g}" '
                    f'd="{d(p, False)}"/>')
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:.10g}mm" height="{h:.10g}mm" '
            f'viewBox="0 0 {w:.10g} {h:.10g}">\n<title>{_xml(pattern.name)}</title>\n'
            + "\n".join(body) + "\n</svg>\n")


def _xml(s: str) -> str:
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


_CAPS = {"butt": "flat", "round": "round", "square": "square"}
_JOINS = {"miter": "mitre", "miter-clip": "mitre", "arcs": "round", "round": "round",
          "bevel": "bevel"}


def stroke_region(line, width: float, cap: str = "butt", join: str = "miter",
                  mitre_limit: float = 4.0, closed: bool = False) -> BaseGeometry:
    """The area a pen of ``width`` (mm) covers along ``line`` (N, 2) mm: SVG's ``cap`` (butt,
    round, square) and ``join`` (miter, round, bevel; miter beyond ``mitre_limit`` — SVG's
    stroke-miterlimit, the same ratio as shapely's — is clipped there). A closed line has no
    caps; a one-point line with a round or square cap is a dot."""
    p = np.asarray(line, np.float64)[:, :2]
    r = width / 2.0
    cap_s, join_s = _CAPS.get(cap, "flat"), _JOINS.get(join, "mitre")
    kw = dict(join_style=join_s, mitre_limit=max(1.0, float(mitre_limit)), quad_segs=16)
    if len(p) < 2 or np.all(np.abs(p - p[0]) <= _EPS):
        if cap_s == "flat":
            return shapely.Polygon()
        return shapely.Point(p[0]).buffer(r, quad_segs=16, cap_style=cap_s)
    if closed and len(p) >= 3:
        ring = shapely.LinearRing(p)
        return shapely.buffer(ring, r, **kw)
    return shapely.buffer(shapely.LineString(p), r, cap_style=cap_s, **kw)
