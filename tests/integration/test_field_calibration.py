"""Scan-field correction from simulated recordings: spots on the plate and marked circles
measured, the use cases and the commands."""

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from insitu.calibrate.fiducials import find_circles
from insitu.calibrate.field_file import load_field_correction
from insitu.cli.field import correct, field
from insitu.errors import CalibrationError, FormatError
from insitu.formats.sequence import Sequence
from insitu.formats.sequence_writer import SequenceWriter
from insitu.services.field import calibrate_field, check_drift, measure_spots
from insitu.services.record import record_field_calibration
from insitu.services.station import simulated
from insitu.sim.rig import default_rig
from insitu.sim.world import SimWorld


def grid(n, half):
    g = np.linspace(-half, half, n)
    return np.array([(x, y) for y in g for x in g])


def rms(e):
    return float(np.sqrt(np.mean(np.sum(np.square(e), 1))))


# -- use cases on a simulated recording -----------------------------------------------------
@pytest.fixture(scope="module")
def correction(field_recording):
    return calibrate_field(field_recording, "rbf")


def test_measure_spots_on_the_plate(field_recording):
    seq = Sequence.open(field_recording)
    m = measure_spots(seq)
    truth = default_rig(3, binning=4)
    true_landing = truth.beams.landing(m.commands)
    assert len(m.commands) >= 35 and m.out_of_view >= 1
    assert all(r == "outside the camera's view" or "no laser spot" in r or "cut off" in r
               for _, r in m.skipped)
    err = m.landed - true_landing           # spot noise plus the operator camera's error
    assert rms(err) < 0.2 and rms(m.deviations) > 0.5


def test_plate_above_z0_is_carried_to_z0_along_the_beam(tmp_path):
    rig = default_rig(3, binning=4)
    out = tmp_path / "raised"
    record_field_calibration(simulated(SimWorld(rig, seed=3)), out, n=5, half_mm=70, heights=(5.0,))
    m = measure_spots(Sequence.open(out))
    err = m.landed - rig.beams.landing(m.commands)
    assert m.plate_z_mm == 5.0 and len(m.commands) >= 15
    assert rms(err) < 0.2                      # read on the plate as is: ~0.8 mm RMS off


@pytest.mark.parametrize("method", ["rbf", "table"])
def test_calibrate_field_reduces_the_deviation(field_recording, correction, method):
    fc = correction if method == "rbf" else calibrate_field(field_recording, "table")
    r = fc.residuals
    assert fc.method == method and r["points"] >= 35
    assert r["before_rms_mm"] > 0.7 and r["cv_rms_mm"] < 0.3 * r["before_rms_mm"]
    assert fc.areas_before[0].n == r["points"] and len(fc.after_mm) == r["points"]
    assert fc.region_mm[1] == pytest.approx(90.0)
    rig = default_rig(3, binning=4)
    Q = grid(6, 60.0)
    true_err = rig.beams.landing(fc.correct(Q)) - Q          # 7 × 7 is coarse; still ~5× better
    assert rms(true_err) < 0.25 * rms(rig.beams.landing(Q) - Q)


def test_plate_not_flat_is_refused(field_recording, tmp_path):
    bad = tmp_path / "rec"
    shutil.copytree(field_recording, bad)
    spec = json.loads((bad / "sequence.json").read_text())
    spec["frames"][5]["plate_z_mm"] = 1.5
    (bad / "sequence.json").write_text(json.dumps(spec))
    with pytest.raises(CalibrationError, match=r"frames\[5\].plate_z_mm: 1.5 differs"):
        calibrate_field(bad)


def test_too_few_spots_and_no_spots(tmp_path):
    few = tmp_path / "few"
    record_field_calibration(simulated(SimWorld(default_rig(3, binning=4), seed=3)), few, n=3, half_mm=50)
    with pytest.raises(CalibrationError, match="only 9 spots measured"):
        calibrate_field(few)
    rig = default_rig(3, binning=4)
    dark = tmp_path / "dark"
    with SequenceWriter(dark, "field-calibration", rig.operator.head.spec(),
                        camera=rig.operator.camera.to_dict()) as w:
        for xy in grid(4, 30.0):
            w.add(np.full((rig.camera.height, rig.camera.width), 11, np.uint8),
                  spot=xy.tolist(), plate_z_mm=0.0)
    with pytest.raises(CalibrationError, match="no usable spot in 16 of 16 frames"):
        calibrate_field(dark)


def test_check_drift(correction, tmp_path):
    rig = default_rig(3, binning=4)
    few = tmp_path / "few"
    record_field_calibration(simulated(SimWorld(rig, seed=8)), few, n=3, half_mm=60)
    same = check_drift(correction, few)
    assert len(same.commands) >= 6 and same.holds, same.max_mm
    moved = replace(rig, distortion=lambda c: rig.distortion(c) + np.array([0.8, -0.3]))
    drifted = tmp_path / "drifted"
    record_field_calibration(simulated(SimWorld(moved, seed=8)), drifted, n=3, half_mm=60)
    d = check_drift(correction, drifted)
    assert not d.holds
    assert np.allclose(np.median(d.residuals, axis=0), [0.8, -0.3], atol=0.15)


# -- commands ---------------------------------------------------------------------------------
_app = typer.Typer()
_cal, _galvo = typer.Typer(), typer.Typer()
_cal.command("field")(field)
_cal.command("height")(lambda: None)        # a second command keeps 'field' a subcommand
_galvo.command("correct")(correct)
_galvo.command("other")(lambda: None)
_app.add_typer(_cal, name="calibrate")
_app.add_typer(_galvo, name="galvo")
runner = CliRunner()


def _run(*args):
    return runner.invoke(_app, [str(a) for a in args])


def _one_line_error(res, message):
    assert res.exit_code == 1, res.output
    assert message in res.output and isinstance(res.exception, SystemExit), res.exception
    assert len(res.output.strip().splitlines()) == 1, res.output


def test_cli_calibrate_and_correct(field_recording, tmp_path):
    out = tmp_path / "FIELD.json"
    res = _run("calibrate", "field", field_recording, "-o", out)
    assert res.exit_code == 0, res.output
    assert "before" in res.output and "after" in res.output
    assert out.is_file() and out.with_suffix(".png").is_file()
    targets = tmp_path / "targets.csv"
    targets.write_text("x,y\n0,0\n-20.5,30\n60,-60\n")
    commands = tmp_path / "commands.csv"
    res = _run("galvo", "correct", out, targets, "-o", commands)
    assert res.exit_code == 0, res.output
    lines = commands.read_text().splitlines()
    assert lines[0] == "x,y" and len(lines) == 4
    K = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    fc = load_field_correction(out)
    assert np.abs(K + fc.delta()(K) - np.array([[0, 0], [-20.5, 30], [60, -60]])).max() < 1e-5


def test_cli_bad_input(field_recording, tmp_path):
    out = tmp_path / "FIELD.json"
    _one_line_error(_run("calibrate", "field", tmp_path / "missing", "-o", out), "missing")
    _one_line_error(_run("calibrate", "field", field_recording, "-o", out, "--method", "magic"),
                    "--method")
    hcal = Path(__file__).parents[1] / "data" / "height-cal-b4"
    _one_line_error(_run("calibrate", "field", hcal, "-o", out),
                    "a 'height-calibration' sequence, not a field calibration")
    assert not out.exists() and not out.with_suffix(".png").exists()

    res = _run("calibrate", "field", field_recording, "-o", out)
    assert res.exit_code == 0, res.output
    targets = tmp_path / "targets.csv"
    commands = tmp_path / "commands.csv"
    targets.write_text("x,y\n0,0\n150,0\n")
    _one_line_error(_run("galvo", "correct", out, targets, "-o", commands),
                    "target 2: [150, 0] mm is outside the scan field")
    targets.write_text("x;y\n0;0\n")
    _one_line_error(_run("galvo", "correct", out, targets, "-o", commands), "header 'x,y'")
    targets.write_text("x,y\n0,zero\n")
    _one_line_error(_run("galvo", "correct", out, targets, "-o", commands), "line 2")
    _one_line_error(_run("galvo", "correct", tmp_path / "nofile.json", targets, "-o", commands),
                    "nofile.json")
    wrong = tmp_path / "wrong.json"
    wrong.write_text(out.read_text().replace('"field-correction"', '"camera"'))
    targets.write_text("x,y\n0,0\n")
    _one_line_error(_run("galvo", "correct", wrong, targets, "-o", commands), "kind")
    assert not commands.exists() and not list(tmp_path.glob(".*"))


# -- the marked-fiducial variant (Mikkelstrup et al. §2.4) -----------------------------------
def test_marked_circles_are_found_where_the_beam_landed(marked_field_recording):
    seq = Sequence.open(marked_field_recording)
    assert len(seq) == 1 and len(seq.frames[0].fiducials) == 81
    rig = default_rig(3, binning=2)
    Q = np.asarray(seq.frames[0].fiducials)
    # with the true camera, the circle fit finds the true landing points (0.1 px at binning 2)
    centres, why = find_circles(seq.read_frame(0), rig.camera, 0.0, Q, 2.0)
    ok = np.array([w is None for w in why])
    assert ok.sum() >= 60 and all(w is None or "outside" in w or "border" in w for w in why)
    assert rms(centres[ok] - rig.beams.landing(Q[ok])) < 0.02
    # through the sequence (operator camera): the deviations and the camera's own error
    m = measure_spots(seq)
    assert len(m.commands) == ok.sum() and rms(m.deviations) > 0.5
    assert rms(m.landed - rig.beams.landing(m.commands)) < 0.2


def test_marked_circles_calibrate_the_field(marked_field_recording):
    cal = calibrate_field(marked_field_recording, "rbf")
    assert cal.residuals["cv_rms_mm"] < 0.03 and cal.residuals["before_rms_mm"] > 0.5


def test_a_frame_without_marks_is_refused(marked_field_recording, tmp_path):
    seq = Sequence.open(marked_field_recording)
    blank = tmp_path / "blank"
    with SequenceWriter(blank, "field-calibration", seq.scan_head.model_dump(),
                        camera=seq.camera.model_dump()) as w:
        w.add(np.full_like(seq.read_frame(0), 90), fiducials=seq.frames[0].fiducials,
              fiducial_diameter_mm=2.0, plate_z_mm=0.0)
    with pytest.raises(CalibrationError, match=r"no usable circle in \d+ of \d+ circles"):
        calibrate_field(blank)
    with pytest.raises(FormatError, match="fiducial_diameter_mm: missing"):
        with SequenceWriter(tmp_path / "nodiam", "field-calibration", seq.scan_head.model_dump(),
                            camera=seq.camera.model_dump()) as w:
            w.add(seq.read_frame(0), fiducials=[[0.0, 0.0]], plate_z_mm=0.0)
    assert not (tmp_path / "nodiam").exists()
