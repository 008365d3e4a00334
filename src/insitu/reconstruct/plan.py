"""The scan plan: which lines the head draws over a region, and whether the region can be
scanned."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from insitu.errors import MeasurementError


def scan_lines(region: Sequence[float], spacing: float, angle_deg: float = 90.0
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Lines over region (x0, x1, y0, y1), mm, one every ``spacing`` mm: along y (the
    default, ``angle_deg`` 90) from x0 on, else at ``angle_deg`` to x across the region,
    each clipped to it (lines shorter than ``spacing`` at the corners are left out)."""
    x0, x1, y0, y1 = map(float, region)
    if angle_deg == 90.0:
        n = int(np.floor((x1 - x0) / spacing + 1e-9)) + 1
        return [(np.array([x, y0]), np.array([x, y1])) for x in x0 + spacing * np.arange(n)]
    a = np.radians(angle_deg)
    t, nrm = np.array([np.cos(a), np.sin(a)]), np.array([np.sin(a), -np.cos(a)])
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]])
    lo, hi = (corners @ nrm).min(), (corners @ nrm).max()
    lines = []
    for c in lo + spacing * np.arange(int(np.floor((hi - lo) / spacing + 1e-9)) + 1):
        s0, s1 = _clip(c * nrm, t, (x0, x1, y0, y1))
        if s1 - s0 >= spacing:
            lines.append((c * nrm + s0 * t, c * nrm + s1 * t))
    return lines


def _clip(p: np.ndarray, t: np.ndarray, region) -> tuple[float, float]:
    """The part (s0, s1) of the line p + s t inside the rectangle (x0, x1, y0, y1)."""
    s0, s1 = -np.inf, np.inf
    for k, (lo, hi) in enumerate((region[:2], region[2:])):
        if abs(t[k]) < 1e-12:
            if not lo <= p[k] <= hi:
                return 0.0, 0.0
            continue
        a, b = sorted(((lo - p[k]) / t[k], (hi - p[k]) / t[k]))
        s0, s1 = max(s0, a), min(s1, b)
    return float(s0), float(max(s1, s0))


def check_region(region: Sequence[float], field_size_mm: Sequence[float]) -> None:
    """MeasurementError unless region (x0, x1, y0, y1), mm, is a rectangle inside the scan
    field of ``field_size_mm`` (width, height) centred on the origin."""
    x0, x1, y0, y1 = region
    half = np.asarray(field_size_mm, float) / 2
    if not (x0 < x1 and y0 < y1):
        raise MeasurementError(f"region {x0:g} {x1:g} {y0:g} {y1:g}: expected X0 < X1 and Y0 < Y1",
                               field="region")
    if max(abs(x0), abs(x1)) > half[0] or max(abs(y0), abs(y1)) > half[1]:
        raise MeasurementError(f"region {x0:g} {x1:g} {y0:g} {y1:g}: outside the scan field "
                               f"±{half[0]:g} × ±{half[1]:g} mm", field="region")


def clip_lines(lines: Sequence, outline: np.ndarray, least_mm: float) -> list:
    """The parts of ``lines`` ((start, end) mm each) inside the convex polygon ``outline``
    (M, 2) mm, each kept in its own direction; a line that misses it or keeps less than
    ``least_mm`` is left out."""
    import shapely

    poly = shapely.Polygon(np.asarray(outline, float))
    out = []
    for a, b in lines:
        piece = poly.intersection(shapely.LineString([a, b]))
        if piece.geom_type != "LineString" or piece.length < least_mm:
            continue
        p, q = np.asarray(piece.coords[0]), np.asarray(piece.coords[-1])
        if np.dot(q - p, np.subtract(b, a)) < 0:
            p, q = q, p
        out.append((p, q))
    return out
