"""What a located pose must reach to be given (:mod:`insitu.locate.part`): 2σ at the rim
within the tolerance, 3σ of the turn within its bound and 2σ of it within the marks' angle
tolerance; and what a scan reference's outline alone holds a part to
(:func:`insitu.locate.uncertainty.outline_hold`)."""

from dataclasses import replace

import numpy as np
import pytest

from insitu.locate.part import LocateRefused, LocateSettings, _pinned
from insitu.locate.search import Solution
from insitu.locate.uncertainty import outline_hold

POSE = Solution(1.0, 2.0, 4.7, 30.0, 1.0, 1.0, 0.02, edges=900, sigma_mm=0.004,
                sigma_deg=0.03, sigma_rim_mm=0.01)


def _pinned_or_why(sol: Solution, settings: LocateSettings) -> str:
    try:
        _pinned(sol, settings, lambda: "what would pin it down: finer lines")
    except LocateRefused as e:
        return str(e)
    return ""


def test_a_turn_within_its_bound_but_not_within_the_angle_tolerance_is_refused():
    """A small part's turn: 1σ 0.03° lies within the 0.1° bound at 3σ and moves its rim
    only 0.005 mm, but 2σ of it is beyond the marks' 0.05°: refused, saying so."""
    why = _pinned_or_why(POSE, LocateSettings())
    assert "0.030°" in why and "0.05°" in why and "finer lines" in why, why
    assert _pinned_or_why(POSE, LocateSettings(turn_tolerance_deg=0.06)) == ""
    assert _pinned_or_why(replace(POSE, sigma_deg=0.024), LocateSettings()) == ""
    assert "0.040°" in _pinned_or_why(replace(POSE, sigma_deg=0.04),
                                       LocateSettings(turn_tolerance_deg=1.0))   # the bound


def _square(half=20.0, spacing=0.1):
    s = np.arange(-half + 1, half - 1, spacing)
    pts, nrm = [], []
    for n, along in (((1, 0), (0, 1)), ((-1, 0), (0, 1)), ((0, 1), (1, 0)), ((0, -1), (1, 0))):
        pts.append(half * np.array(n, float) + s[:, None] * np.array(along, float))
        nrm.append(np.tile(np.array(n, float), (len(s), 1)))
    return np.vstack(pts), np.vstack(nrm)


def test_what_a_reference_outline_alone_holds_a_part_to():
    """Each side of a 40 mm square placed to 1σ 0.015 mm: x and y each to 0.015/√2 (two
    sides each), its turn from its sides' tilt; a side twice as uncertain weakens x alone."""
    xy, n = _square()
    rim = np.array([[-20.0, -20], [20, -20], [20, 20], [-20, 20]])
    sigma, tilt = np.full(len(xy), 0.015), np.full(len(xy), 0.01)
    h = outline_hold(xy, n, np.full(len(xy), 5.0), sigma, tilt, rim)
    assert h.x_mm == pytest.approx(0.015 / np.sqrt(2), rel=0.05)
    assert h.y_mm == pytest.approx(0.015 / np.sqrt(2), rel=0.05)
    assert 0.005 < h.turn_deg < 0.03 and h.rim_mm > h.x_mm
    far = xy[:, 0] > 19.9                                  # the side at x = +20 unsure
    sigma[far], tilt[far] = 0.06, 0.04
    weak = outline_hold(xy, n, np.full(len(xy), 5.0), sigma, tilt, rim)
    assert weak.x_mm > 1.3 * h.x_mm and weak.y_mm == pytest.approx(h.y_mm, rel=0.05)
    assert abs(weak.weakest[0]) > 0.99
