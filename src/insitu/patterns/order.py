"""Path ordering (shorter laser-off jumps) and simplification, on polylines in mm.

Ordering is greedy nearest neighbour on path ends (a KD-tree, paths may be run backwards),
then 2-opt with neighbour lists: reversing a run of the tour reverses each path in it, which
is how 2-opt treats paths that may be marked either way. Closed paths (first == last point)
are then started at their vertex nearest the previous path's end.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import shapely

from insitu.patterns.model import Pattern

_FLIP = bytes.maketrans(b"\x00\x01", b"\x01\x00")


def jump_length(paths, start=(0.0, 0.0)) -> float:
    """Total laser-off travel, mm: from ``start`` to the first path, then end to next start."""
    if not len(paths):
        return 0.0
    firsts = np.array([p[0] for p in paths], np.float64)
    lasts = np.array([start] + [p[-1] for p in paths[:-1]], np.float64)
    return float(np.linalg.norm(firsts - lasts, axis=1).sum())


def _nearest_neighbour(entry: np.ndarray, exit_: np.ndarray, start) -> tuple[list, list]:
    """Greedy tour. entry, exit_: (n, 2, 2) points of each unit run forwards (variant 0) or
    backwards (variant 1). Returns (units in order, variant of each)."""
    from scipy.spatial import cKDTree

    n = len(entry)
    pts = entry.reshape(-1, 2)
    alive = np.ones(2 * n, bool)
    ids = np.arange(2 * n)
    tree = cKDTree(pts)
    cur = np.asarray(start, np.float64)
    order, var = [], []
    dead_in_tree = 0
    for _ in range(n):
        k = 8
        while True:
            kk = min(k, len(ids))
            _, ii = tree.query(cur, k=kk)
            cand = ids[np.atleast_1d(ii)]
            ok = alive[cand]
            if ok.any():
                pick = int(cand[ok.argmax()])
                break
            k *= 4
        u, v = divmod(pick, 2)
        alive[2 * u] = alive[2 * u + 1] = False
        order.append(u)
        var.append(v)
        cur = exit_[u, v]
        dead_in_tree += 2
        if dead_in_tree > len(ids) // 2 and len(ids) > 64:
            ids = np.flatnonzero(alive)
            if len(ids):
                tree = cKDTree(pts[ids])
            dead_in_tree = 0
    return order, var


def _two_opt(entry, exit_, sym, start, order, var, neighbours: int = 10,
             max_moves_per_unit: int = 50) -> tuple[list, list]:
    """Improve a tour by 2-opt moves found through the ``neighbours`` nearest path ends.

    Positions 1..n hold the units, position 0 is the fixed ``start``; the tour ends open.
    Reversing positions i..j flips each unit's variant; runs with an asymmetric unit (one whose
    backward run is not its forward run reversed) are never reversed.
    """
    from scipy.spatial import cKDTree

    n = len(order)
    if n < 2:
        return order, var
    ent = entry.reshape(-1, 2)
    ext = exit_.reshape(-1, 2)
    k = min(neighbours + 1, 2 * n)
    tree = cKDTree(ent)
    _, nb_exit = tree.query(ext, k=k)  # neighbours (entry ids) of each exit point
    _, nb_ent = tree.query(ent, k=k)
    _, nb_start = tree.query(np.asarray(start, np.float64), k=k)
    nb_exit, nb_ent = nb_exit.reshape(2 * n, k).tolist(), nb_ent.reshape(2 * n, k).tolist()
    nb_start = np.atleast_1d(nb_start).tolist()
    ex, ey = ent[:, 0].tolist(), ent[:, 1].tolist()
    xx, xy = ext[:, 0].tolist(), ext[:, 1].tolist()
    sym = [bool(s) for s in sym]
    all_sym = all(sym)
    sx, sy = float(start[0]), float(start[1])
    U = [-1] + list(order)
    Un = np.array(U, np.int64)  # U as an array, for fast slice updates of pos
    F = bytearray([0] + list(var))
    pos = np.zeros(n, np.int64)
    pos[Un[1:]] = np.arange(1, n + 1)
    hyp = math.hypot

    def E(p):  # entry id at position p
        return 2 * U[p] + F[p]

    def X(p):  # exit point of position p
        if p == 0:
            return sx, sy
        q = 2 * U[p] + F[p]
        return xx[q], xy[q]

    def ok(i, j):
        return all_sym or all(sym[U[t]] for t in range(i, j + 1))

    def apply(i, j):
        U[i:j + 1] = U[i:j + 1][::-1]
        Un[i:j + 1] = Un[i:j + 1][::-1].copy()
        F[i:j + 1] = F[i:j + 1][::-1].translate(_FLIP)
        pos[Un[i:j + 1]] = np.arange(i, j + 1)

    def try_boundary(i) -> tuple[int, int] | None:
        """Apply the first improving move that changes the jump into position i."""
        ax, ay = X(i - 1)
        b = E(i)
        bx, by = ex[b], ey[b]
        g = hyp(ax - bx, ay - by)
        if g < 1e-12:
            return None
        # new edge X(i-1)–X(p): the exit of some unit near a
        for q in nb_start if i == 1 else nb_exit[2 * U[i - 1] + F[i - 1]]:
            dq = hyp(ax - ex[q], ay - ey[q])
            if dq >= g:
                break
            u, v = divmod(q, 2)
            p = int(pos[u])
            if v == F[p] or not sym[u] or p == i - 1:
                continue  # q is not the current exit of its unit
            if p >= i:
                delta = dq - g
                if p < n:
                    e2 = E(p + 1)
                    px, py = X(p)
                    delta += hyp(bx - ex[e2], by - ey[e2]) - hyp(px - ex[e2], py - ey[e2])
                lo, hi = i, p
            else:
                e1 = E(p + 1)
                px, py = X(p)
                delta = dq + hyp(ex[e1] - bx, ey[e1] - by) - hyp(px - ex[e1], py - ey[e1]) - g
                lo, hi = p + 1, i - 1
            if delta < -1e-9 and ok(lo, hi):
                apply(lo, hi)
                return lo, hi
        # new edge E(i)–E(p): the entry of some unit near b
        for q in nb_ent[b]:
            dq = hyp(bx - ex[q], by - ey[q])
            if dq >= g:
                break
            u, v = divmod(q, 2)
            p = int(pos[u])
            if v != F[p] or p == i:
                continue  # q is not the current entry of its unit
            cx, cy = X(p - 1)
            delta = hyp(ax - cx, ay - cy) + dq - g - hyp(cx - ex[q], cy - ey[q])
            lo, hi = (i, p - 1) if p > i else (p, i - 1)
            if delta < -1e-9 and ok(lo, hi):
                apply(lo, hi)
                return lo, hi
        return None

    # don't-look bits: recheck only units next to an edge that changed
    queue = deque(U[1:])
    queued = [True] * n
    budget = max_moves_per_unit * n
    while queue and budget > 0:
        u = queue.popleft()
        queued[u] = False
        pu = int(pos[u])
        for i in (pu, pu + 1):
            if i > n:
                continue
            moved = try_boundary(i)
            if moved:
                budget -= 1
                lo, hi = moved
                for p in (lo - 1, lo, hi, hi + 1):
                    if 1 <= p <= n and not queued[U[p]]:
                        queued[U[p]] = True
                        queue.append(U[p])
                break
    return U[1:], list(F[1:])


def order_units(entry, exit_, sym, start=(0.0, 0.0), improve: bool = True):
    """Order n units that each run forwards (variant 0) or backwards (variant 1).

    entry, exit_: (n, 2, 2) float64 mm, [unit, variant] → first and last marked point.
    sym: (n,) bool, True when variant 1 is variant 0 reversed (entry[:, 1] == exit_[:, 0]).
    Returns (order, variants): the unit indices in marking order and the variant of each.
    """
    entry = np.asarray(entry, np.float64).reshape(-1, 2, 2)
    exit_ = np.asarray(exit_, np.float64).reshape(-1, 2, 2)
    if not len(entry):
        return [], []
    order, var = _nearest_neighbour(entry, exit_, start)
    if improve:
        order, var = _two_opt(entry, exit_, sym, start, order, var)
    return order, var


def start_nearest(loop: np.ndarray, at) -> np.ndarray:
    """A closed polyline (first == last) restarted at its vertex nearest ``at``."""
    ring = loop[:-1]
    j = int(np.argmin(((ring - np.asarray(at)) ** 2).sum(axis=1)))
    if j == 0:
        return loop
    r = np.roll(ring, -j, axis=0)
    return np.vstack([r, r[:1]])


def is_closed(p: np.ndarray) -> bool:
    return len(p) >= 3 and bool(np.all(p[0] == p[-1]))


def order_paths(paths, start=(0.0, 0.0), reversible: bool = True) -> list[np.ndarray]:
    """The polylines ((N, 2) mm each) reordered, and reversed where it helps
    (``reversible``), to cut the jump length from ``start``. Closed paths (first == last)
    start at the vertex nearest the previous end. Returns new arrays; the input is unchanged."""
    paths = [np.asarray(p, np.float64) for p in paths if len(p)]
    if not paths:
        return []
    first = np.array([p[0] for p in paths])
    last = np.array([p[-1] for p in paths])
    closed = np.array([is_closed(p) for p in paths])
    entry = np.stack([first, last if reversible else first], axis=1)
    exit_ = np.stack([last, first if reversible else last], axis=1)
    entry[closed, 1], exit_[closed, 1] = first[closed], first[closed]
    sym = np.full(len(paths), reversible) | closed
    order, var = order_units(entry, exit_, sym, start)
    out = []
    cur = np.asarray(start, np.float64)
    for u, v in zip(order, var):
        p = paths[u][::-1] if v and reversible and not closed[u] else paths[u]
        if closed[u]:
            p = start_nearest(p, cur)
        out.append(p.copy())
        cur = p[-1]
    return out


def simplify(paths, tol_mm: float):
    """Douglas–Peucker: fewer vertices, every original point within ``tol_mm`` of the result;
    ends kept. ``paths``: a list of (N, 2) polylines (returns a list) or a Pattern (returns a
    Pattern, contours simplified as closed rings)."""
    if isinstance(paths, Pattern):
        rings = [np.vstack([c, c[:1]]) for c in paths.contours]
        cs = [r[:-1] for r in simplify(rings, tol_mm) if len(r) >= 4]
        return Pattern(tuple(cs), tuple(simplify(list(paths.paths), tol_mm)), paths.name,
                       paths.frame)
    paths = [np.asarray(p, np.float64) for p in paths]
    if not paths or tol_mm <= 0:
        return [p.copy() for p in paths]
    lines = [shapely.LineString(p if len(p) >= 2 else np.vstack([p, p])) for p in paths]
    out = shapely.simplify(lines, tol_mm, preserve_topology=False)
    return [np.asarray(shapely.get_coordinates(g)) if len(p) >= 2 else p.copy()
            for g, p in zip(out, paths)]
