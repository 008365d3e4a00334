"""Where the part lies in a scan region: a sparse first pass of lines along y whose points
stand above the table (the scan's z = 0, the height calibration's reference plane) bounds
it, so that the part's dense scan sweeps its lines over the part and its margin only, not
over the whole region (a part turned 45° fills 40 % of its bounding box), and searches them
only at the heights the pass saw.

Each line of the pass that meets the part gives a chord: its lowest and highest point in y
above the table. The part's footprint is taken as convex (its convex hull's, for one that
is not): beyond two neighbouring chords it lies between the lines through their ends
(:func:`chord_outline`), and it lies between the pass's first and last line that missed it.
That bound, within the hull of the chords grown by the pass's spacing, grown by the margin,
is the outline the dense lines are clipped to. A part lower than :data:`ABOVE_TABLE_MM`, or a
pass none of whose points stands above the table or the outlier tests, gives no outline:
the whole region is scanned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.devices.clock import StepTimer
from insitu.errors import MeasurementError
from insitu.reconstruct.packing import line_ids
from insitu.reconstruct.plan import scan_lines
from insitu.services.scan import ScanResult, scan_live
from insitu.services.station import Station

ABOVE_TABLE_MM = 0.5
"""Points this much above the table are the part's (the table's own points lie within a few
hundredths of a millimetre of it)."""

CHORD_SLACK_MM = 1.5
"""How far a chord's measured end may lie from the part's edge: each bound through two
chords' ends is loosened by it. Where a line crosses a low step's wall at a glancing angle
(near a turned part's corner) the camera loses up to 3 mm of it; the hull of the other
chords restores most of that, and the dense scan's check (:func:`scan_found`) the rest."""

HEIGHT_PAD_MM = 3.0
"""The dense lines are searched this far below and above the heights the pass saw (a part's
feature between its lines may stand higher)."""


@dataclass(frozen=True)
class Survey:
    """What a first pass found: the ``outline`` (M, 2) mm, world x, y, the dense lines are
    clipped to (None: the whole region), the ``heights`` (low, high) mm to search them at
    (None: the head's focus range) and its station seconds ``station_s`` (None: a real
    rig's)."""

    outline: np.ndarray | None
    heights: tuple[float, float] | None
    station_s: float | None = None


def survey_part(station: Station, region, spacing_mm: float, margin_mm: float,
                height_cal=None, speed_mm_s: float | None = None) -> Survey:
    """A pass of lines along y ``spacing_mm`` apart over ``region`` (x0, x1, y0, y1) mm (no
    room-light frame) and what it bounds: the part's outline grown by ``margin_mm``
    (:func:`chord_outline`) and the heights its points span, padded by
    :data:`HEIGHT_PAD_MM` (within the head's focus range)."""
    timer = StepTimer(station.clock)
    try:
        cloud = scan_live(station, spacing_mm, region, height_cal, speed_mm_s=speed_mm_s,
                          room_light=False).cloud
    except MeasurementError:             # no point stood the outlier tests: the whole region
        return Survey(None, None, timer.elapsed().station)
    spent = timer.elapsed().station
    lo_z, hi_z = station.rig.head.z_range_mm
    z = cloud.points[:, 2]
    heights = (max(float(z.min()) - HEIGHT_PAD_MM, lo_z), min(float(z.max()) + HEIGHT_PAD_MM,
                                                              hi_z))
    lines = scan_lines(region, spacing_mm)
    place = {k: i for i, k in enumerate(line_ids(lines))}
    every = np.asarray(cloud.attributes["line"], int)
    top = z > ABOVE_TABLE_MM
    chords = {}
    for k in np.unique(every[top]):
        xy = cloud.points[top & (every == k), :2]
        chords[place[int(k)]] = (xy[np.argmin(xy[:, 1])], xy[np.argmax(xy[:, 1])])
    seen = {place[int(k)] for k in np.unique(every)}
    xs = [float(a[0]) for a, _ in lines]
    return Survey(chord_outline(chords, seen, xs, region, spacing_mm, margin_mm), heights,
                  spent)


def scan_found(station: Station, region, survey_mm: float, margin_mm: float,
               height_cal=None, **scan) -> ScanResult:
    """:func:`~insitu.services.scan.scan_live` over ``region`` with its lines only over the
    outline a first pass of lines ``survey_mm`` apart found (:func:`survey_part`), searched
    at the heights it saw; ``scan``: scan_live's other arguments (``spacing`` first). When a
    point of the part lies nearer than half the margin to the outline's edge (the part may
    reach beyond it: a chord the camera could not see whole), the whole region is scanned
    again at the head's focus range. The survey's time counts in the scan's."""
    found = survey_part(station, region, survey_mm, margin_mm, height_cal,
                        scan.get("speed_mm_s"))
    if found.outline is None:
        return scan_live(station, region=region, height_cal=height_cal, **scan)
    result = scan_live(station, region=region, height_cal=height_cal, heights=found.heights,
                       within=found.outline, **scan)
    if not reaches_edge(result.cloud.points, found.outline, margin_mm / 2):
        return result
    return scan_live(station, region=region, height_cal=height_cal, **scan)


def reaches_edge(points: np.ndarray, outline: np.ndarray, within_mm: float) -> bool:
    """Whether a point (N, 3) mm of the part (:data:`ABOVE_TABLE_MM` above the table) lies
    within ``within_mm`` of the edge of ``outline`` (M, 2) mm."""
    import shapely

    top = points[points[:, 2] > ABOVE_TABLE_MM, :2]
    if not len(top):
        return False
    inner = shapely.Polygon(outline).buffer(-within_mm)
    return not bool(np.all(shapely.contains_xy(inner, top[:, 0], top[:, 1])))


def chord_outline(chords: dict, seen, xs, region, spacing_mm: float, margin_mm: float
                  ) -> np.ndarray | None:
    """The convex outline (M, 2) mm within which a convex part lies, grown by ``margin_mm``,
    from ``chords`` (line index → (its lowest, its highest) point (x, y) mm above the
    table) of lines along y at ``xs`` mm over ``region`` (x0, x1, y0, y1), ``seen``: the
    indices of the lines that gave points at all (one that gave none, hidden, bounds
    nothing); None when no two seen lines next to each other met the part.

    Each chord is first taken as long as the hull of all of them makes it (a chord whose end
    was hidden from the camera). Beyond two neighbouring chords, up to the next seen line,
    a convex part lies below the line through their highest points and above the line
    through their lowest (else the nearer chord would reach further), each loosened by
    :data:`CHORD_SLACK_MM`; in x it lies between the nearest seen lines either side that
    missed it. That bound, within the chords' hull grown by the spacing, holds the hull."""
    import shapely

    known = sorted(seen)
    pairs = [(i, j) for i, j in zip(known, known[1:]) if i in chords and j in chords]
    if not pairs:
        return None
    ends = np.array([p for c in chords.values() for p in c])
    hull = shapely.MultiPoint(ends).convex_hull
    full = {k: _hull_chord(hull, *c) for k, c in chords.items()}
    x0, x1, y0, y1 = map(float, region)
    low, high = y0 - margin_mm - spacing_mm, y1 + margin_mm + spacing_mm
    after = {i: j for i, j in zip(known, known[1:])}
    before = {j: i for i, j in zip(known, known[1:])}
    hit = sorted(chords)
    left = xs[before[hit[0]]] if hit[0] in before else x0 - spacing_mm
    right = xs[after[hit[-1]]] if hit[-1] in after else x1 + spacing_mm
    bound = shapely.box(left, low, right, high)
    for i, j in pairs:
        for near, far, end in ((j, i, xs[after[j]] if j in after else right),
                               (i, j, xs[before[i]] if i in before else left)):
            (bn, tn), (bf, tf) = full[near], full[far]
            upper = _beyond(tf, tn, end, CHORD_SLACK_MM)
            lower = _beyond(bf, bn, end, -CHORD_SLACK_MM)
            if upper is None or lower is None:
                continue
            ys = [y for _, y in (*upper, *lower)]
            floor, roof = min(*ys, low) - 1.0, max(*ys, high) + 1.0
            below = shapely.Polygon([*upper, (end, floor), (upper[0][0], floor)])
            above = shapely.Polygon([*lower, (end, roof), (lower[0][0], roof)])
            zone = shapely.box(min(upper[0][0], end), floor, max(upper[0][0], end), roof)
            bound = bound.difference(zone.difference(below.intersection(above)))
    kept = bound.intersection(hull.buffer(spacing_mm + CHORD_SLACK_MM)).union(hull)
    return np.asarray(kept.convex_hull.buffer(margin_mm).exterior.coords)


def _hull_chord(hull, bottom, top) -> tuple[np.ndarray, np.ndarray]:
    """The chord from ``bottom`` to ``top`` carried on to where it leaves ``hull``."""
    import shapely

    b, t = np.asarray(bottom, float), np.asarray(top, float)
    along = t - b
    if np.hypot(*along) < 1e-9:
        return b, t
    along = along / np.hypot(*along) * 1e3
    piece = hull.intersection(shapely.LineString([b - along, t + along]))
    if piece.is_empty or piece.geom_type != "LineString":
        return b, t
    p = np.asarray(piece.coords)
    return p[np.argmin(p[:, 1])], p[np.argmax(p[:, 1])]


def _beyond(far, near, end: float, slack: float) -> tuple | None:
    """The two points (at ``near``'s x and at x = ``end``) of the line from ``far`` through
    ``near`` carried on to ``end``, its slope loosened by ``slack`` mm at each point (> 0:
    upward beyond ``near``); None when ``end`` is not beyond ``near``."""
    far, near = np.asarray(far, float), np.asarray(near, float)
    run = near[0] - far[0]
    if abs(run) < 1e-9 or (end - near[0]) * run <= 0:
        return None
    slope = (near[1] + slack - (far[1] - slack)) / run
    start = (near[0], near[1] + slack)
    return start, (end, near[1] + slack + slope * (end - near[0]))
