"""The band's compiled passes (reconstruct.band_kernel) give what their array forms give:
the light plane's points at the two heights, and the two edges interpolated by np.interp,
their np.fmin / np.fmax and the sign of the median of their difference."""

from __future__ import annotations

import numpy as np

from insitu.reconstruct.band_kernel import band_edges, plane_points
from insitu.vision.chains import median_of


def _edges_array_form(xa, ya, xb, yb, n, sign, margin):
    grid = np.arange(n, dtype=np.float64)
    ea = np.interp(grid, xa, ya, left=np.nan, right=np.nan)
    eb = np.interp(grid, xb, yb, left=np.nan, right=np.nan)
    rise = (eb - ea) * sign
    rise = rise[np.isfinite(rise)]
    side = int(np.sign(median_of(rise))) if len(rise) else 0
    return np.fmin(ea, eb) - margin, np.fmax(ea, eb) + margin, side


def test_band_edges_equal_the_array_form():
    rng = np.random.default_rng(21)
    sides = set()
    for k in range(300):
        n = int(rng.integers(1, 400))
        edges = []
        for _ in range(2):
            m = int(rng.integers(2, 40))
            x = np.sort(rng.uniform(-60, n + 60, m).round(int(rng.integers(0, 3))))
            x[rng.random(m) < 0.1] = x[0]                    # ties
            edges += [np.sort(x), rng.uniform(0, 300, m)]
        if k % 4 == 0:                                       # edges a fixed step apart
            edges[2], edges[3] = edges[0], edges[1] + rng.choice([-3.0, 0.0, 3.0])
        if k % 9 == 0:                                       # ends on whole positions
            edges[0][[0, -1]] = 0.0, float(n - 1)
        if k % 4 == 1:                     # half the rises below 0: the middle two's mean
            n = 2 * int(rng.integers(2, 200))
            top = float(n - 1)
            edges = [np.array([0.0, top]), np.zeros(2), np.array([0.0, top]),
                     np.array([-1.0, 1.0 + rng.choice([-1e-3, 1e-3])])]
        sign = float(rng.choice([-1.0, 0.0, 1.0]))
        got = band_edges(*edges, n, sign, 25.0)
        want = _edges_array_form(*edges, n, sign, 25.0)
        assert np.array_equal(got[0], want[0], equal_nan=True), k
        assert np.array_equal(got[1], want[1], equal_nan=True), k
        assert got[2] == want[2], k
        sides.add(want[2])
    assert sides == {-1, 0, 1}


def test_plane_points_equal_the_array_form():
    rng = np.random.default_rng(22)
    s = np.linspace(-0.05, 1.05, 96)
    weights = np.stack((1 - s, s))
    for _ in range(20):
        start, end = rng.uniform(-60, 60, 2), rng.uniform(-60, 60, 2)
        plane = np.append(rng.normal(size=3), rng.uniform(-50, 50))
        z = np.sort(rng.uniform(-30, 30, 2))
        for axis in (0, 1):
            p = np.zeros((2 * 96 + 2, 3))
            q = p[:-2].reshape(2, 96, 3)
            q[..., :2] = weights[0][:, None] * start + weights[1][:, None] * end
            q[..., 2] = z[:, None]
            q[..., axis] = -(plane[1 - axis] * q[..., 1 - axis] + plane[2] * z[:, None]
                             + plane[3]) / plane[axis]
            p[-2:, :2] = start, end
            assert np.array_equal(plane_points(start, end, plane, z, weights, axis), p)
