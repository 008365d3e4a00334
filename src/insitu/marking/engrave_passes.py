"""A crossed scan's passes: its lines grouped by their direction (each pass measures a pocket on
its own: :func:`~insitu.marking.engrave_depth.measure_depth` takes lines of one direction), and
the passes' depths of a pocket combined by their inverse variances (the passes cross the floor's
speckle on different lines, so their errors are independent, but for the error all of a scan's
lines over a pocket share, which combining keeps).

A line's direction is the principal axis of its own points; a line too short or too sparse to
set a pass's direction (:data:`MIN_LINE_MM`, :data:`MIN_LINE_POINTS`: e.g. a crossed pass's
lines cut short by the region's corners) joins the pass whose direction its points spread
least across, or where they cannot tell, the pass of the nearest line id (a scan numbers the
lines of a pass one after the other, :func:`~insitu.reconstruct.packing.line_ids`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from insitu.errors import MeasurementError

MIN_APART_DEG = 10.0
"""Lines whose directions lie at least this far apart (with no line between) are in different
passes; a pass's lines spread over less than this (nearer, they are one pass, and
:func:`~insitu.marking.engrave_depth.measure_depth` checks they are parallel enough over
each pocket: :data:`~insitu.marking.engrave_walls.MAX_CROSSING`; a line over a deep pocket
turns by a degree or two where the light plane is tilted)."""
OBLIQUE_DEG = 10.0
"""A pass whose lines cross a pocket's walls more than this more obliquely than another pass's
is left out of the pocket's combined depth (:func:`obliquity`): ``measure_depth``'s walls'
zones assume lines along or across the walls, and a pass at 45° to them reads short (the
simulated plate, spent seeds: −14.5 µm mean, |err|/σ 2.1; ``docs/accuracy.md``)."""
MIN_LINE_MM = 1.0
MIN_LINE_POINTS = 10
"""A line with fewer points, or shorter, has no direction of its own."""


@dataclass(frozen=True)
class LinePass:
    """One pass of parallel lines: its ``lines`` (K,) ids, ``angle_deg`` to x in [0, 180)
    and ``number`` (1: the first recorded)."""

    number: int
    lines: np.ndarray
    angle_deg: float

    def holds(self, line: np.ndarray) -> np.ndarray:
        """(N,) bool: which of the points on ``line`` (N,) ids lie on this pass."""
        return np.isin(line, self.lines)

    def describe(self) -> str:
        """"pass 1 (lines at 90° to x)"."""
        return f"pass {self.number} (lines at {round(self.angle_deg) % 180}° to x)"


def line_angles(xy: np.ndarray, line: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each line of ``xy`` (N, 2) mm on ``line`` (N,): (ids (L,), direction to x (L,)
    degrees in [0, 180), length (L,) mm (its points' spread along it × √12), points (L,))."""
    ids, n, cxx, cyy, cxy = _moments(xy, line)
    angle = np.degrees(0.5 * np.arctan2(2 * cxy, cxx - cyy)) % 180.0
    major = 0.5 * (cxx + cyy) + np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy ** 2)
    return ids, angle, np.sqrt(12 * major), n


def _moments(xy: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, ...]:
    """Each line's (ids, points, and the variances xx, yy and covariance xy of its points)."""
    ids, inv = np.unique(line, return_inverse=True)
    inv = inv.ravel()
    n = np.bincount(inv).astype(float)
    mx, my = (np.bincount(inv, xy[:, k]) / n for k in (0, 1))
    dx, dy = xy[:, 0] - mx[inv], xy[:, 1] - my[inv]
    return (ids, n, *(np.bincount(inv, v) / n for v in (dx * dx, dy * dy, dx * dy)))


def line_passes(xy: np.ndarray, line: np.ndarray, first: np.ndarray | None = None
                ) -> list[LinePass]:
    """The passes of a scan's points ``xy`` (N, 2) mm on ``line`` (N,): one, or two whose
    directions lie at least :data:`MIN_APART_DEG` apart, the one nearest ``first`` (2,), the
    first recorded pass's direction (None: along y, as insitu records it), numbered 1.
    MeasurementError for lines in more than two directions, or one pass's spread over
    :data:`MIN_APART_DEG` or more."""
    ids, angle, length, n = line_angles(xy, line)
    own = (length >= MIN_LINE_MM) & (n >= MIN_LINE_POINTS)
    if not own.any():
        own[:] = True
    order = np.argsort(angle[own])
    a = angle[own][order]
    gaps = np.diff(np.append(a, a[0] + 180.0))
    cuts = set(np.flatnonzero(gaps >= MIN_APART_DEG).tolist())
    group, g = np.zeros(len(a), int), 0
    start = min(cuts) + 1 if cuts else 0             # after a gap: no group wraps around
    for j in range(len(a)):
        i = (start + j) % len(a)
        group[i] = g
        g += i in cuts
    count = max(len(cuts), 1)
    centres = [_mean_angle(a[group == k]) for k in range(count)]
    spread = max(2 * _apart(x, centres[k]) for x, k in zip(a, group))
    if count > 2 or not cuts or spread >= MIN_APART_DEG:
        listed = ", ".join(f"{c:.0f}°" for c in centres) if count > 2 else (
            f"{a.min():.0f}° … {a.max():.0f}°")
        raise MeasurementError(f"the scan's lines run in more than two directions ({listed} "
                               "to x): measure from a scan of one pass of parallel lines, or "
                               "of two crossed ones")
    of_line = np.empty(len(ids), int)
    known = np.flatnonzero(own)[order]
    of_line[known] = group
    rest = np.flatnonzero(~own)
    if len(rest):
        of_line[rest] = _short_lines(xy, line, ids, known, of_line, rest, centres)
    first = np.array([0.0, 1.0]) if first is None else np.asarray(first, float)[:2]
    towards = np.degrees(np.arctan2(first[1], first[0])) % 180.0
    rank = np.argsort([_apart(c, towards) for c in centres], kind="stable")
    return [LinePass(k + 1, ids[of_line == r], round(float(centres[r]), 3))
            for k, r in enumerate(rank)]


def _short_lines(xy, line, ids, known, of_line, rest, centres) -> np.ndarray:
    """The group of each line ``rest`` (indices into ``ids``) too short to have a direction
    of its own: the group whose direction its points spread least across, or where that
    cannot tell (fewer than 3 points, or a group as good as the other), the group of the
    nearest line id of ``known``."""
    _, n, cxx, cyy, cxy = (m[rest] for m in _moments(xy, line))
    across = []
    for c in centres:
        a = np.radians(c)
        across.append(np.sin(a) ** 2 * cxx - 2 * np.sin(a) * np.cos(a) * cxy
                      + np.cos(a) ** 2 * cyy)
    across = np.array(across)
    best = np.argmin(across, axis=0)
    tells = (n >= 3) & (np.sort(across, axis=0)[-1] > 4 * np.sort(across, axis=0)[0] + 1e-8) \
        if len(centres) > 1 else np.ones(len(rest), bool)
    by_id = known[np.argsort(ids[known])]
    k = np.searchsorted(ids[by_id], ids[rest])
    lo, hi = by_id[np.clip(k - 1, 0, len(by_id) - 1)], by_id[np.clip(k, 0, len(by_id) - 1)]
    near = np.where(np.abs(ids[lo] - ids[rest]) <= np.abs(ids[hi] - ids[rest]), lo, hi)
    return np.where(tells, best, of_line[near])


def _mean_angle(a: np.ndarray) -> float:
    """The mean of directions ``a`` (degrees, period 180), in [0, 180)."""
    r = np.radians(2 * a)
    return float(np.degrees(np.arctan2(np.sin(r).mean(), np.cos(r).mean())) / 2 % 180.0)


def _apart(a: float, b: float) -> float:
    """Degrees between two directions (period 180)."""
    d = abs(a - b) % 180.0
    return float(min(d, 180.0 - d))


def obliquity(angle_deg: float, region) -> float:
    """Degrees in [0, 45] by which lines at ``angle_deg`` to x miss running along or across
    the walls of ``region`` (shapely, world mm; its walls' direction: the sides of its
    minimum rotated rectangle)."""
    xy = np.asarray(region.minimum_rotated_rectangle.exterior.coords)
    side = xy[1] - xy[0]
    d = (angle_deg - np.degrees(np.arctan2(side[1], side[0]))) % 90.0
    return float(min(d, 90.0 - d))


def combine(depths: Sequence[tuple[float, float]], shared_mm: float = 0.0
            ) -> tuple[float, float]:
    """(mean, standard error) mm of a pocket from its passes' (mean, standard error) mm,
    measured each on its own: the means weighted by the inverse variances of their own
    errors, independent between the passes; ``shared_mm`` (rms) of each standard error is an
    error common to all the passes (one scan's:
    :data:`~insitu.marking.engrave_stats.SHARED_MM`), which combining does not shrink."""
    if not depths:
        raise ValueError("no pass to combine")
    own = np.array([max(sem ** 2 - shared_mm ** 2, 1e-6 * sem ** 2) for _, sem in depths])
    w = 1.0 / own
    mean = float(np.dot(w, [m for m, _ in depths]) / w.sum())
    return mean, float(np.sqrt(1.0 / w.sum() + shared_mm ** 2))
