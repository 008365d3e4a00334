"""Measurement on frames our code did not draw: the step block recorded by another renderer
(shared/recordings, beside the repository; heavier speckle, textured ambient light, mirror
images of the line in step faces), Method 2 with the height calibration fitted from its own
recorded plate. truth.json is read only to score."""

import json

import numpy as np
import pytest

from insitu.sim.workpieces import make_workpiece


@pytest.fixture(scope="module")
def measured(independent_scan):
    folder, result = independent_scan
    p = json.loads((folder / "truth.json").read_text())["workpiece"]["params"]
    part = make_workpiece("step-block", length=p["y_size"], width=p["x_size"],
                          heights=p["heights"], x=p["center"][0], y=p["center"][1])
    return result, part


def _top_errors(part, pts, margin):
    z = part.height(pts[:, 0], pts[:, 1])
    ok = np.isfinite(z) & (z > 0.5)
    for dx, dy in ((margin, 0), (-margin, 0), (0, margin), (0, -margin)):
        zn = part.height(pts[:, 0] + dx, pts[:, 1] + dy)
        ok &= np.isfinite(zn) & (np.abs(zn - z) < 0.3)
    return pts[ok, 2] - z[ok]


def test_method_2_holds_on_an_independent_recording(measured):
    result, part = measured
    e = _top_errors(part, result.cloud.points, 0.3)
    assert len(e) > 10000
    assert np.sqrt(np.mean(e**2)) <= 0.03          # docs/accuracy.md: 0.027
    assert np.abs(e).max() <= 0.15                 # docs/accuracy.md: 0.100 (a ghost, a wrong
    # line, is millimetres off)
    assert result.summary.frames_with_line == 16
