"""Which way a higher surface moves a scan line across itself in the image
(insitu.reconstruct.plane.band_and_side), against the camera's projection of the light plane."""

from __future__ import annotations

import numpy as np
import pytest

from insitu.reconstruct.plane import band_and_side
from insitu.sim.rig import default_rig

PIVOT = 350.0


@pytest.mark.parametrize("start, end", [((10.0, -40.0), (10.0, 40.0)),
                                        ((-30.0, -30.0), (30.0, 30.0)),
                                        ((-40.0, 5.0), (40.0, 5.0)),
                                        ((-20.0, 35.0), (20.0, -35.0))])
def test_a_higher_surface_moves_the_line_to_the_side_it_names(start, end):
    cam = default_rig(0, binning=4).camera
    ends = cam.project(np.array([[*start, 0.0], [*end, 0.0]]))
    along_rows = bool(abs(ends[1, 0] - ends[0, 0]) >= abs(ends[1, 1] - ends[0, 1]))
    mid = (np.asarray(start) + np.asarray(end)) / 2
    # the light plane holds the pivot and the line: above the line's middle at height z
    # it passes through the pivot's ray to that middle, at mid · (1 − z / pivot)
    p = np.array([[*(mid * (1 - z / PIVOT)), z] for z in (0.0, 10.0)])
    uv = cam.project(p)
    across = 1 if along_rows else 0
    want = int(np.sign(uv[1, across] - uv[0, across]))
    assert want != 0
    for z_range in ((0.0, 10.0), (10.0, 0.0)):
        assert band_and_side(cam, start, end, PIVOT, z_range, 0.0, False, along_rows)[2] == want
