"""Patterns: hatching, ordering the paths to save jumps, simplification."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

from insitu.patterns import (
    Pattern,
    hatch,
    jump_length,
    load_pattern,
    order_paths,
    simplify,
)
from insitu.patterns.fill import offset
from insitu.patterns.order import order_units
from pattern_shapes import SAMPLES, SQUARE, square_with_hole

# --- hatching ---------------------------------------------------------------------------------

def _segments(polys):
    return [q for q in polys if len(q) == 2 and not np.allclose(q[0], q[-1])]


@pytest.mark.parametrize("angle", [0.0, 30.0, 90.0, -61.0])
@pytest.mark.parametrize("spacing", [0.04, 0.12, 0.5])
def test_hatch_spacing_exact(angle, spacing):
    p = load_pattern("text:S8").placed((0, 0), 12)
    segs = _segments(hatch(p, spacing, angle_deg=angle, outline=False))
    a = math.radians(angle)
    d = np.array([math.cos(a), math.sin(a)])
    nrm = np.array([-math.sin(a), math.cos(a)])
    for s in segs:                                             # along the hatch angle
        v = s[1] - s[0]
        assert abs(v @ nrm) < 1e-9 * max(1, np.linalg.norm(v)) and abs(v @ d) > 0
    offs = np.unique(np.round(np.array([s[0] @ nrm for s in segs]) / spacing, 6))
    steps = np.diff(offs)
    assert np.allclose(steps, np.round(steps), atol=1e-6)    # on the grid of lines
    assert np.all(np.round(steps) >= 1)
    y = np.array(sorted({round(float(s[0] @ nrm), 9) for s in segs}))
    k = np.round((y - y[0]) / spacing)
    assert np.allclose(y - y[0], k * spacing, atol=1e-9)     # exactly spacing apart


def test_hatch_square_line_count_and_centering():
    segs = _segments(hatch(SQUARE, 0.1, outline=False))
    ys = np.sort([s[0, 1] for s in segs])
    assert len(segs) == 100 and ys[0] == pytest.approx(0.05) and ys[-1] == pytest.approx(9.95)
    assert np.allclose(np.diff(ys), 0.1, atol=1e-12)
    assert all(abs(s[1, 0] - s[0, 0]) == pytest.approx(10) for s in segs)


def test_joined_hatch_runs_back_and_forth_only_along_a_straight_edge():
    """An L: its 100 lines joined where they end along one edge (across by one spacing),
    split where the L's step moves the end (a step across would mark outside)."""
    ell = Pattern((np.array([[0, 0], [10, 0], [10, 5], [4, 5], [4, 10], [0, 10]], float),))
    plain = hatch(ell, 0.1, outline=False)
    lines = hatch(ell, 0.1, outline=False, join=True)
    assert len(plain) == 100 and len(lines) <= 3
    d = np.concatenate([np.diff(q, axis=0) for q in lines])
    across = np.abs(d[:, 1]) > 1e-9
    assert np.allclose(d[across, 0], 0.0) and np.allclose(np.abs(d[across, 1]), 0.1)
    assert across.sum() == 100 - len(lines)
    assert np.abs(d[~across, 0]).sum() == pytest.approx(            # the same lines
        sum(float(np.linalg.norm(q[1] - q[0])) for q in plain))


def test_hatch_inside_cross_doubles_and_hole_unfilled():
    for p in (load_pattern(str(SAMPLES / "logo.svg")), load_pattern("text:&g@"),
              square_with_hole()):
        geom = p.to_shapely().buffer(1e-9)
        segs = _segments(hatch(p, 0.1, angle_deg=17, outline=False))
        assert segs and all(geom.contains(shapely.LineString(s)) for s in segs)
    holed = square_with_hole()
    hole = shapely.Point(5, 5).buffer(2 * math.cos(math.pi / 64) - 1e-6, 256)
    one = _segments(hatch(holed, 0.2, outline=False))
    two = _segments(hatch(holed, 0.2, outline=False, cross=True))
    assert not any(hole.intersects(shapely.LineString(s)) for s in two)
    assert len(two) == 2 * len(one)
    assert len(_segments(hatch(SQUARE, 0.1, cross=True, outline=False))) == 200


def test_hatch_outline_paths_direction_and_offset():
    p = Pattern(SQUARE.contours, ([[20, 0], [25, 5]],), "sq+line")
    out = hatch(p, 0.5)
    closed = [q for q in out if len(q) > 2 and np.array_equal(q[0], q[-1])]
    assert len(closed) == 1 and len(closed[0]) == 5
    assert any(len(q) == 2 and {tuple(q[0]), tuple(q[1])} == {(20, 0), (25, 5)} for q in out)
    assert not [q for q in hatch(p, 0.5, outline=False) if len(q) > 2]
    one_way = _segments(hatch(SQUARE, 0.5, outline=False, bidirectional=False))
    assert all(s[1, 0] > s[0, 0] for s in one_way)
    both = _segments(hatch(SQUARE, 0.5, outline=False))
    assert {bool(s[1, 0] > s[0, 0]) for s in both} == {True, False}
    assert all(np.linalg.norm(both[i + 1][0] - both[i][1]) == pytest.approx(0.5)
               for i in range(len(both) - 1))                  # one block, back and forth
    shrunk = hatch(SQUARE, 0.5, offset_mm=-0.5)
    ring = [q for q in shrunk if len(q) == 5][0]
    assert ring.min(axis=0) == pytest.approx((0.5, 0.5)) and ring.max(axis=0) == \
        pytest.approx((9.5, 9.5))
    assert offset(SQUARE, 1).to_shapely().area == pytest.approx(144)


def test_hatch_covers_the_area():
    p = load_pattern("qr:insitu").placed((0, 0), 30)
    segs = _segments(hatch(p, 0.04, outline=False))
    length = sum(np.linalg.norm(s[1] - s[0]) for s in segs)
    assert length * 0.04 == pytest.approx(p.to_shapely().area, rel=0.01)


# --- ordering and simplification ----------------------------------------------------------------

def test_order_paths_cuts_jumps_and_keeps_every_path():
    rng = np.random.default_rng(3)
    segs = [rng.uniform(0, 100, (2, 2)) for _ in range(500)]
    out = order_paths(segs, start=(0, 0))
    assert jump_length(out) < 0.1 * jump_length(segs)
    key = lambda s: tuple(sorted(map(tuple, np.round(s, 12))))   # noqa: E731
    assert sorted(map(key, out)) == sorted(map(key, segs))
    fixed = order_paths(segs, reversible=False)
    assert jump_length(fixed) < 0.2 * jump_length(segs)
    assert {tuple(map(tuple, s)) for s in fixed} == {tuple(map(tuple, s)) for s in segs}


def test_two_opt_improves_on_nearest_neighbour():
    rng = np.random.default_rng(4)
    segs = [rng.uniform(0, 100, (2, 2)) for _ in range(400)]
    first, last = np.array([s[0] for s in segs]), np.array([s[1] for s in segs])
    e, x = np.stack([first, last], 1), np.stack([last, first], 1)
    sym = np.ones(len(segs), bool)

    def length(order, var):
        return jump_length([segs[u][::-1] if v else segs[u] for u, v in zip(order, var)])

    assert length(*order_units(e, x, sym)) < 0.95 * length(*order_units(e, x, sym,
                                                                        improve=False))


def test_closed_paths_start_near_and_jump_length():
    loop = np.array([[10, 10], [11, 10], [11, 11], [10, 11], [10, 10]], float)
    out = order_paths([loop], start=(11.2, 11.3))
    assert np.array_equal(out[0][0], (11, 11)) and np.array_equal(out[0][0], out[0][-1])
    assert jump_length([np.array([[1, 0], [2, 0]]), np.array([[2, 3], [0, 0]])]) == \
        pytest.approx(1 + 3)
    assert order_paths([]) == [] and jump_length([]) == 0


@pytest.mark.parametrize("tol", [0.001, 0.01, 0.1])
def test_simplify_error_within_tolerance(tol):
    rng = np.random.default_rng(5)
    t = np.linspace(0, 6 * np.pi, 2000)
    wavy = np.column_stack([t, np.sin(t) * 3 + rng.normal(0, tol / 5, t.size)])
    out = simplify([wavy], tol)[0]
    assert len(out) < len(wavy) / 3
    assert np.array_equal(out[0], wavy[0]) and np.array_equal(out[-1], wavy[-1])
    line = shapely.LineString(out)
    err = max(line.distance(shapely.Point(q)) for q in wavy)
    assert err <= tol + 1e-12
    og = load_pattern("text:Og").to_shapely()
    pat = simplify(load_pattern("text:Og"), tol).to_shapely()
    assert pat.symmetric_difference(og).area < og.length * tol
    assert pat.hausdorff_distance(og) <= tol + 1e-9
