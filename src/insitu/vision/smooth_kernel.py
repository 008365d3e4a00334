"""The smoothing of the centres along the line (:func:`~insitu.vision.extract.smooth_centres`)
as one compiled pass: each point's quadratic over the window of its stretch."""

from __future__ import annotations

import numpy as np

from insitu.vision.detect_kernel import compiled
from insitu.vision.steger_kernel import moment_fit


@compiled
def local_quadratic(col, v, first, last, h):
    """v (n,) smoothed: each point's value of the quadratic (a straight line below 5 points
    or where the quadratic is degenerate; v itself below 2) fitted to the points of its
    stretch within ±h columns of its window's centre — the point's column, shifted to stay
    h columns inside the stretch (its middle when the stretch is shorter than the window).
    col (n,) int64 non-decreasing; stretches: points first[s] … last[s]."""
    out = np.empty(len(v))
    for s in range(len(first)):
        a, b = first[s], last[s]
        span = col[b] - col[a]
        lo = a                                     # the window's first point
        for i in range(a, b + 1):
            p = col[i] - col[a]
            centre = min(max(p, h), span - h) if span - h >= h else span // 2
            while col[lo] - col[a] < centre - h:
                lo += 1
            m0 = m1 = m2 = m3 = m4 = t0 = t1 = t2 = 0.0
            j = lo
            while j <= b and col[j] - col[a] <= centre + h:
                x = np.float64(col[j] - col[a] - centre)
                m0 += 1.0
                m1 += x
                m2 += x * x
                m3 += x * x * x
                m4 += x * x * x * x
                t0 += v[j]
                t1 += v[j] * x
                t2 += v[j] * (x * x)
                j += 1
            det, a0, a1, a2 = moment_fit(m0, m1, m2, m3, m4, t0, t1, t2)
            x = np.float64(p - centre)
            det2 = m0 * m2 - m1 ** 2
            if m0 >= 5 and abs(det) > 1e-9:
                out[i] = a0 + a1 * x + a2 * x * x
            elif m0 >= 2 and abs(det2) > 1e-9:
                b1 = (m0 * t1 - m1 * t0) / det2
                out[i] = (t0 - b1 * m1) / m0 + b1 * x
            else:
                out[i] = v[i]
    return out
