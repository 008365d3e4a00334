"""``insitu galvo check FIELD.json REC``: a field correction is re-checked with a few spots —
it holds on the same head (exit 0), and a head whose field shifted fails (exit 1, one line
naming the worst point)."""

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.calibrate.field_file import load_field_correction, save_field_correction
from insitu.cli.main import app
from insitu.services.field import calibrate_field, check_drift
from insitu.services.record import record_field_calibration
from insitu.services.station import simulated
from insitu.sim.rig import default_rig
from insitu.sim.world import SimWorld

runner = CliRunner()
SEED = 3


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def field(tmp_path_factory):
    """A field correction from 9 × 9 spots (binning 4), and the rig it was made on."""
    d = tmp_path_factory.mktemp("drift")
    rig = default_rig(SEED, binning=4)
    record_field_calibration(simulated(SimWorld(rig, seed=SEED)), d / "fcal", n=9)
    out = d / "field.json"
    save_field_correction(out, calibrate_field(d / "fcal"))
    return out, rig


def _spots(rig, out):
    """3 × 3 spots over ±60 mm, another noise seed than the calibration's."""
    return record_field_calibration(simulated(SimWorld(rig, seed=8)), out, n=3, half_mm=60.0)


def test_the_correction_holds_on_the_same_head(field, tmp_path):
    fc, rig = field
    res = _run("galvo", "check", fc, _spots(rig, tmp_path / "same"))
    assert res.exit_code == 0, res.output
    assert "predicted" in res.output and "measured" in res.output
    assert re.search(r"holds: RMS [\d.]+ mm, max [\d.]+ mm \(point \d\), tolerance", res.output)
    assert len(re.findall(r"^│ \d ", res.output, re.M)) == 9          # a row per point


def test_a_shifted_field_fails_naming_the_worst_point(field, tmp_path):
    fc, rig = field
    shifted = replace(rig, distortion=lambda c: rig.distortion(c) + np.array([0.8, -0.3]))
    rec = _spots(shifted, tmp_path / "shifted")
    res = _run("galvo", "check", fc, rec)
    assert res.exit_code == 1, res.output
    assert isinstance(res.exception, SystemExit), res.exception    # not an uncaught error
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    errors = [ln for ln in lines                                                # not progress
              if not re.fullmatch(r"drift check: \d+ of 9 points", ln)]
    assert lines[-2] == "drift check: 9 of 9 points", res.stderr
    assert len(errors) == 1 and "no longer holds" in errors[0], res.stderr
    d = check_drift(load_field_correction(fc), rec)
    k = int(np.argmax(np.linalg.norm(d.residuals, axis=1)))
    c = d.commands[k]
    assert f"point {k + 1} (command [{c[0]:g}, {c[1]:g}] mm)" in errors[0]
    assert np.allclose(np.median(d.residuals, axis=0), [0.8, -0.3], atol=0.15)
    # a generous tolerance lets the same recording pass
    assert _run("galvo", "check", fc, rec, "--tolerance", 10).exit_code == 0


@pytest.mark.parametrize("case, message", [
    ("no-field", "nofile.json"),
    ("not-spots", "a 'height-calibration' sequence, not a field calibration"),
    ("tolerance", "--tolerance: 0 is outside 1e-06 … 100 mm"),
])
def test_bad_input_one_line_error(field, tmp_path, case, message):
    fc, rig = field
    spots = Path(__file__).parents[1] / "data" / "height-cal-b4" if case == "not-spots" else (
        _spots(rig, tmp_path / "s"))
    args = {"no-field": (tmp_path / "nofile.json", spots),
            "not-spots": (fc, spots),
            "tolerance": (fc, spots, "--tolerance", 0)}[case]
    res = _run("galvo", "check", *args)
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and message in lines[0], res.output
