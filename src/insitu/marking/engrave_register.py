"""Where a depth scan's points lie against the marks: the shift along the scan lines that
puts the pocket's walls, as the scan sees them, on the outline the marks were cut to.

A scan's points are placed by the camera's calibration; the marks by the head. Along a line,
a point's place comes from the camera's ray alone, and a calibration good to 0.02° and
0.08 mm puts it ~0.1 mm off (the simulated rig's seed 2: 0.13 mm). On a floor that is not
flat (a wood's rings: ±12 % of the depth every 1.5 mm) every cell then reads the floor a
tenth of a millimetre away, an error that repeats scan after scan (its slope × the shift:
≈ 7 µm rms a cell on beech) and that the per-cell passes then put in the wrong place.
Across the lines a point's place is the light plane's, which the head sets as it sets the
marks': no shift to find there.

The walls the lines cross show the shift: along each line the depth steps from the top to
the floor where the outline is. The step fitted over every such crossing (a shift along the
lines, and a common move of every wall into or out of the pocket, which a shift cannot
mimic as walls face both ways) finds it to ~0.02 mm."""

from __future__ import annotations

import numpy as np

STEP_MM = 0.005
"""The grid the shift is searched on, mm."""
_EROSION_MM = np.arange(-0.1, 0.1001, 0.01)     # a common move of the walls into the pocket
_REACH_MM = 0.35                                # points this near the outline show the step
MIN_STEP_MM = 0.02
"""A floor shallower than this (the step's height) is not registered: no shift."""


def wall_shift(x: np.ndarray, y: np.ndarray, depth: np.ndarray, along: np.ndarray,
               outline, span_mm: float) -> float:
    """The shift (mm, along ``along`` (2,) the lines' unit direction) to take off the points
    (``x``, ``y``) (N,) world mm, ``depth`` (N,) mm below the top, so that their step from the
    top to the floor lies on ``outline`` (:class:`~insitu.marking.engrave_depth.Outline`):
    least squares of a step of the floor's median depth, over shifts within ±``span_mm``.
    0 when the floor is shallower than :data:`MIN_STEP_MM`, or no wall is crossed."""
    dist = outline.distance(x, y)
    floor = dist > 0.2
    if floor.sum() < 20:
        return 0.0
    step = float(np.median(depth[floor]))
    near = np.abs(dist) < _REACH_MM + span_mm
    if step < MIN_STEP_MM or near.sum() < 20:
        return 0.0
    x, y, d = x[near], y[near], depth[near]
    shifts = np.arange(-span_mm, span_mm + STEP_MM / 2, STEP_MM)
    q = outline.distance(x[None, :] - shifts[:, None] * along[0],
                         y[None, :] - shifts[:, None] * along[1])
    cost = np.empty((len(shifts), len(_EROSION_MM)))
    for k, e in enumerate(_EROSION_MM):
        r = np.clip(d[None, :] - step * (q > e), -step, step)
        cost[:, k] = (r ** 2).sum(1)
    best = shifts[np.unravel_index(np.argmin(cost), cost.shape)[0]]
    if np.ptp(cost.min(1)) <= 0:        # no crossed wall: every shift fits alike
        return 0.0
    return float(best)
