"""What a located pose must reach to be given (:mod:`insitu.locate.refusal`): 2σ at the rim
within the tolerance and 3σ of the turn within its bound (2σ of the turn within the marks'
angle tolerance only when one is set); and what a scan reference's outline alone holds a part
to (:func:`insitu.locate.uncertainty.outline_hold`)."""

from dataclasses import replace

import numpy as np
import pytest

from insitu.locate.part import LocateSettings
from insitu.locate.refusal import LocateRefused, pinned
from insitu.locate.search import Solution
from insitu.locate.uncertainty import outline_hold

POSE = Solution(1.0, 2.0, 4.7, 30.0, 1.0, 1.0, 0.02, edges=900, sigma_mm=0.004,
                sigma_deg=0.03, sigma_rim_mm=0.01)


def _pinned_or_why(sol: Solution, settings: LocateSettings) -> str:
    try:
        pinned(sol, settings, lambda: "what would pin it down: finer lines")
    except LocateRefused as e:
        return str(e)
    return ""


def test_a_small_part_is_given_when_its_rim_and_its_turn_bound_hold():
    """The insert with CAD + frame, two sides seen: 1σ 0.01 mm at the rim and 0.03° (the
    per-edge tilt floor), 3σ of the turn 0.09° within the 0.1° bound: given, though 2σ of its
    turn (0.06°) exceeds 0.05° — unless a turn tolerance is asked for."""
    assert _pinned_or_why(POSE, LocateSettings()) == ""
    why = _pinned_or_why(POSE, LocateSettings(turn_tolerance_deg=0.05))
    assert "0.030°" in why and "0.05°" in why and "finer lines" in why, why


def test_a_turn_whose_3_sigma_exceeds_its_bound_is_refused_whatever_the_rim():
    """1σ 0.04°: 3σ 0.12° beyond the 0.1° bound — no pose given that may lie 0.1° off, even
    where the rim (1σ 0.01 mm) holds; the refusal names both and what would pin it down."""
    why = _pinned_or_why(replace(POSE, sigma_deg=0.04), LocateSettings())
    assert "0.040°" in why and "0.1°" in why and "finer lines" in why, why
    assert "0.05 mm" in why and "3σ of the turn" in why, why
    assert _pinned_or_why(replace(POSE, sigma_deg=0.04), LocateSettings(turn_bound_deg=0.13)
                          ) == ""
    assert "0.030 mm" in _pinned_or_why(replace(POSE, sigma_rim_mm=0.03), LocateSettings())


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
