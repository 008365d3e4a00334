"""The part found by a sparse first pass: the dense scan's lines clipped to the outline its
chords bound."""

import numpy as np
import pytest
import shapely
from shapely import affinity

from insitu.reconstruct.plan import clip_lines
from insitu.services.survey import chord_outline


def test_lines_are_clipped_to_a_convex_outline_in_their_own_direction():
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    lines = [(np.array([x, 20.0]), np.array([x, -20.0])) for x in (-1.0, 2.0, 9.9, 5.0)]
    clipped = clip_lines(lines, square, 0.5)
    assert len(clipped) == 3                                # x = −1 misses it
    assert all(a[1] == pytest.approx(10.0) and b[1] == pytest.approx(0.0) for a, b in clipped)
    corner = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    assert len(clip_lines([(np.array([9.8, -5.0]), np.array([9.8, 5.0]))], corner, 0.5)) == 0


def _chords(footprint, xs, region, rng):
    """Each line x of ``xs`` that meets ``footprint``: its lowest and highest point, 0.05 mm
    noise."""
    out = {}
    for k, x in enumerate(xs):
        piece = footprint.intersection(shapely.LineString([(x, region[2]), (x, region[3])]))
        if not piece.is_empty:
            y = np.array(piece.coords)[:, 1] + rng.normal(0.0, 0.05, 2)
            out[k] = (np.array([x, y.min()]), np.array([x, y.max()]))
    return out


@pytest.mark.parametrize("turn", [0.0, 10.0, 45.0, 80.0, 129.5, 35.0])
def test_a_turned_part_is_bounded_by_its_chords_not_by_its_bounding_box(turn):
    rng = np.random.default_rng(int(turn))
    part = affinity.translate(affinity.rotate(shapely.box(-40, -10, 40, 10), turn), 3.3, -7.1)
    x0, y0, x1, y1 = part.bounds
    margin, spacing = 4.0, 4.0
    region = (x0 - margin, x1 + margin, y0 - margin, y1 + margin)
    xs = list(np.arange(region[0], region[1] + 1e-9, spacing))
    chords = _chords(part.buffer(-0.1), xs, region, rng)
    outline = shapely.Polygon(chord_outline(chords, range(len(xs)), xs, region, spacing,
                                            margin))
    assert outline.contains(part.buffer(margin - 0.4))      # the part and its margin
    box = shapely.box(region[0], region[2], region[1], region[3])
    if 30.0 < turn % 90.0 < 60.0:                               # not its bounding box
        assert outline.intersection(box).area < 0.55 * box.area
    first = min(chords)
    assert chord_outline({first: chords[first]}, range(len(xs)), xs, region, spacing,
                         margin) is None                     # one line: only the region
