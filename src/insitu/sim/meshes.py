"""Closed triangle meshes from numpy: polygon triangulation, prisms and height-field blocks.

Every builder returns ``(vertices (N, 3) float64 mm, triangles (M, 3) int32)``: closed,
edge-manifold, triangles counter-clockwise seen from outside (outward normals), no repeated
vertices, no degenerate triangles. Vertex coordinates are the given numbers (no rescaling).
"""

from __future__ import annotations

import numpy as np


def signed_area(poly: np.ndarray) -> float:
    """Shoelace area of a closed polygon (N, 2); > 0 when counter-clockwise."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def segments_for_arc(radius: float, span_rad: float, chord_tol: float, multiple: int = 1) -> int:
    """Fewest segments (a multiple of ``multiple``) for an arc whose chord error ≤ chord_tol."""
    step = 2.0 * np.arccos(max(1.0 - chord_tol / radius, -1.0))
    n = max(int(np.ceil(span_rad / step - 1e-12)), 1)
    return int(np.ceil(n / multiple) * multiple)


def earclip(poly: np.ndarray) -> np.ndarray:
    """Triangulate a simple polygon (N, 2), counter-clockwise, no repeated points.

    Returns (N - 2, 3) int32 indices, each triangle counter-clockwise with positive area.
    """
    poly = np.asarray(poly, float)
    n = len(poly)
    if signed_area(poly) <= 0:
        raise ValueError("earclip: polygon must be counter-clockwise")
    scale = float(np.ptp(poly, axis=0).max()) ** 2
    idx = list(range(n))
    tris: list[tuple[int, int, int]] = []
    while len(idx) > 3:
        m = len(idx)
        for k in range(m):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % m]
            if _cross(poly[a], poly[b], poly[c]) <= 1e-12 * scale:
                continue                            # reflex or flat: not an ear
            tri = poly[[a, b, c]]
            inside = False
            for j in idx:
                if j in (a, b, c) or any(np.array_equal(poly[j], t) for t in tri):
                    continue
                p = poly[j]
                if (_cross(tri[0], tri[1], p) >= 0 and _cross(tri[1], tri[2], p) >= 0
                        and _cross(tri[2], tri[0], p) >= 0):
                    inside = True
                    break
            if not inside:
                tris.append((a, b, c))
                del idx[k]
                break
        else:
            raise ValueError("earclip: no ear found (polygon not simple?)")
    tris.append((idx[0], idx[1], idx[2]))
    return np.array(tris, np.int32)


def zipper(outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """Triangulate the ring between two closed counter-clockwise loops (N, 2) and (K, 2) that
    are star-shaped about the origin, ``inner`` strictly inside ``outer``.

    Vertices are merged by polar angle. Returns (N + K, 3) int32 indices into
    ``vstack([outer, inner])``, counter-clockwise. Checked: every triangle has positive area
    and the areas add up to the ring's area (so they neither overlap nor leave gaps).
    """
    def start(loop: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ang = np.arctan2(loop[:, 1], loop[:, 0])
        order = np.roll(np.arange(len(loop)), -int(np.argmin(ang)))
        a = np.unwrap(ang[order])
        return order, np.append(a, a[0] + 2 * np.pi)

    n, k = len(outer), len(inner)
    oi, oa = start(outer)
    ii, ia = start(inner)
    ii = ii + n
    tris = []
    i = j = 0
    while i < n or j < k:
        if j == k or (i < n and oa[i + 1] <= ia[j + 1]):
            tris.append((oi[i], oi[(i + 1) % n], ii[j % k]))
            i += 1
        else:
            tris.append((ii[j], oi[i % n], ii[(j + 1) % k]))
            j += 1
    tris = np.array(tris, np.int32)
    pts = np.vstack([outer, inner])
    p0, p1, p2 = pts[tris[:, 0]], pts[tris[:, 1]], pts[tris[:, 2]]
    area = 0.5 * ((p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1])
                  - (p1[:, 1] - p0[:, 1]) * (p2[:, 0] - p0[:, 0]))
    ring = signed_area(outer) - signed_area(inner)
    if area.min() <= 0 or abs(area.sum() - ring) > 1e-9 * abs(ring):
        raise ValueError("zipper: the loops are not nested star-shaped loops about the origin")
    return tris


def prism(loops: list[np.ndarray], cap: np.ndarray, w0: float, w1: float,
          axis: str = "z") -> tuple[np.ndarray, np.ndarray]:
    """Extrude a planar region between w0 < w1.

    loops: boundary loops (Ni, 2) in the (u, v) plane, the outer one counter-clockwise and
    holes clockwise (material on the left). cap: (M, 3) counter-clockwise triangles indexing
    ``vstack(loops)``. axis: the extrusion axis; (u, v, w) = (x, y, z) for "z",
    (y, z, x) for "x", (z, x, y) for "y" (cyclic, so orientation is kept).
    """
    pts = np.vstack(loops)
    n = len(pts)
    verts = np.vstack([np.column_stack([pts, np.full(n, w0)]),
                       np.column_stack([pts, np.full(n, w1)])])
    faces = [cap + n, cap[:, ::-1]]                       # top (+w) and bottom (−w)
    off = 0
    for loop in loops:
        a = off + np.arange(len(loop))
        b = np.roll(a, -1)
        faces.append(np.column_stack([a, b, b + n]))      # wall: outward on the loop's right
        faces.append(np.column_stack([a, b + n, a + n]))
        off += len(loop)
    roll = {"z": 0, "x": 1, "y": 2}[axis]
    verts = np.roll(verts, roll, axis=1)
    return verts, np.vstack(faces).astype(np.int32)


def heightfield_block(xs: np.ndarray, ys: np.ndarray, top: np.ndarray,
                      z0: float) -> tuple[np.ndarray, np.ndarray]:
    """Solid over the rectangle xs[0]..xs[-1] × ys[0]..ys[-1] between z0 and a height field.

    xs (nx,), ys (ny,): increasing grid coordinates, mm; top (nx, ny): heights at the grid
    nodes, all > z0. Top: grid of triangles; sides: vertical walls; bottom: fan about the
    rectangle's centre.
    """
    xs, ys, top = np.asarray(xs, float), np.asarray(ys, float), np.asarray(top, float)
    nx, ny = len(xs), len(ys)
    if top.shape != (nx, ny) or nx < 2 or ny < 2:
        raise ValueError("heightfield_block: need top of shape (len(xs), len(ys)), ≥ 2 × 2")
    if not np.all(top > z0):
        raise ValueError("heightfield_block: the top must lie above the bottom")
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    verts = [np.column_stack([gx.ravel(), gy.ravel(), top.ravel()])]
    g = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = g[:-1, :-1].ravel(), g[1:, :-1].ravel(), g[1:, 1:].ravel(), g[:-1, 1:].ravel()
    faces = [np.column_stack([a, b, c]), np.column_stack([a, c, d])]
    # boundary of the grid, counter-clockwise seen from +z
    ring = np.concatenate([g[:-1, 0], g[-1, :-1], g[:0:-1, -1], g[0, :0:-1]])
    m, base = len(ring), nx * ny
    bottom = verts[0][ring].copy()
    bottom[:, 2] = z0
    centre = [0.5 * (xs[0] + xs[-1]), 0.5 * (ys[0] + ys[-1]), z0]
    verts += [bottom, [centre]]
    t0 = ring
    t1 = np.roll(ring, -1)
    b0 = base + np.arange(m)
    b1 = np.roll(b0, -1)
    faces += [np.column_stack([b0, b1, t1]), np.column_stack([b0, t1, t0]),
              np.column_stack([np.full(m, base + m), b1, b0])]
    return np.vstack(verts).astype(float), np.vstack(faces).astype(np.int32)


def place(vertices: np.ndarray, x: float, y: float, angle_deg: float) -> np.ndarray:
    """Rotate (N, 3) vertices by angle_deg about +z through the origin, then shift by (x, y)."""
    out = np.array(vertices, float)
    if angle_deg:
        c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
        out[:, :2] = out[:, :2] @ np.array([[c, s], [-s, c]])
    out[:, 0] += x
    out[:, 1] += y
    return out


def unplace(x: np.ndarray, y: np.ndarray, px: float, py: float,
            angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) → the part's own frame, undoing :func:`place`."""
    u, v = np.asarray(x, float) - px, np.asarray(y, float) - py
    if angle_deg:
        c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
        u, v = c * u + s * v, -s * u + c * v
    return u, v
