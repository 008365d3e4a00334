"""insitu.reconstruct.plane.line_band: the line's direction and band from one projection, the
same values as line_runs_along_rows and band_and_side."""

import numpy as np

from insitu.reconstruct.plane import band_and_side, line_band, line_runs_along_rows
from insitu.sim.rig import default_rig


def test_line_band_is_the_two_calls():
    cam = default_rig().camera
    lines = [([-30.0, -45.0], [-30.0, 45.0]), ([-45.0, 10.0], [45.0, 10.0]),
             ([5.0, -40.0], [20.0, 35.0]), ([-40.0, -5.0], [38.0, 12.0])]
    seen = set()
    for start, end in lines:
        for z in ((-25.0, 25.0), (3.0, -2.0)):
            rows, lo, hi, side = line_band(cam, start, end, 300.0, z, 20.0, False)
            want = line_runs_along_rows(cam, start, end)
            assert rows == want
            seen.add(rows)
            for got, exp in zip((lo, hi, side), band_and_side(cam, start, end, 300.0, z, 20.0,
                                                              False, want)):
                np.testing.assert_array_equal(got, exp)
    assert seen == {True, False}                    # lines along the rows and the columns
