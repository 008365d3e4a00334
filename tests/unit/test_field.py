"""Scan-field correction: the RBF network (OLS), the correction table, the iterated correction,
the file, the use cases and the commands, on synthetic fields and a small simulated recording."""

import json
import shutil
from pathlib import Path
from dataclasses import replace

import numpy as np
import pytest
import typer
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from insitu.calibrate.fiducials import find_circles
from insitu.services.station import simulated
from insitu.calibrate.field import (CorrectionTable, RBFNetwork, fit_rbf, fit_table, folds,
                                    invert, ols_order, select_rbf, select_table, table_nodes)
from insitu.calibrate.field_areas import area_table
from insitu.calibrate.field_file import (FieldCorrection, correction_from_file,
                                         load_field_correction, model_spec,
                                         save_field_correction)
from insitu.cli.field import correct, field
from insitu.sim.world import SimWorld
from insitu.errors import CalibrationError, ConfigError, FormatError, SafetyError
from insitu.formats.sequence import Sequence, SequenceWriter
from insitu.geometry.distortion import PolynomialFieldDistortion
from insitu.services.field import calibrate_field, check_drift, measure_spots
from insitu.services.record import record_field_calibration, record_marked_field_calibration
from insitu.sim.rig import default_rig

FIELD = PolynomialFieldDistortion.random(np.random.default_rng(4), rms_mm=0.8)


def grid(n, half):
    g = np.linspace(-half, half, n)
    return np.array([(x, y) for y in g for x in g])


@pytest.fixture(scope="module")
def training():
    X = grid(15, 90.0)
    D = FIELD(X) + np.random.default_rng(0).normal(0, 0.003, X.shape)
    held_out = grid(14, 90.0 - 90.0 / 14)          # between the training points
    return X, D, held_out


def rms(e):
    return float(np.sqrt(np.mean(np.sum(np.square(e), 1))))


# -- models -------------------------------------------------------------------------------
def test_ols_selection_reduces_the_error_and_stops_at_the_goal(training):
    X, D, _ = training
    order, mse = ols_order(X, D, sigma=45.0, mse_goal=1e-4)
    assert len(set(order)) == len(order) and 0 < len(order) < len(X) // 2
    assert np.all(np.diff(mse) <= 1e-15) and mse[-1] <= 1e-4 < mse[-2]
    net = fit_rbf(X, D, 45.0, 1e-4, order=order)
    assert np.mean((net(X) - D) ** 2) == pytest.approx(mse[-1], rel=1e-6)


def test_rbf_recovers_a_known_smooth_field(training):
    X, D, V = training
    sel = select_rbf(X, D)
    assert isinstance(sel.model, RBFNetwork)
    assert rms(sel.model(V) - FIELD(V)) < 0.01            # field ~0.8 mm RMS
    assert sel.cv.rms < 0.02 and len(sel.cv.fold_rms) == 5
    assert sel.tried[0] is sel.cv and sel.cv.rms <= min(c.rms for c in sel.tried)


def test_table_recovers_a_known_smooth_field(training):
    X, D, V = training
    sel = select_table(X, D, (-100, 100, -100, 100))
    assert isinstance(sel.model, CorrectionTable)
    assert rms(sel.model(V) - FIELD(V)) < 0.015
    assert sel.cv.rms < 0.03


def test_table_interpolates_its_nodes_like_rect_bivariate_spline():
    from scipy.interpolate import RectBivariateSpline
    rng = np.random.default_rng(0)
    xn, yn = np.linspace(-100, 100, 9), np.linspace(-100, 100, 7)
    t = CorrectionTable(xn, yn, rng.normal(size=(7, 9, 2)))
    p = rng.uniform(-100, 100, (40, 2))
    ref = RectBivariateSpline(xn, yn, t.values[:, :, 1].T, kx=3, ky=3, s=0).ev(p[:, 0], p[:, 1])
    assert np.allclose(t(p)[:, 1], ref, atol=1e-12)


def test_table_fills_nodes_without_data_smoothly():
    X = grid(9, 60.0)
    xn, yn = table_nodes((-100, 100, -100, 100), X, 20.0)
    lin = lambda p: np.column_stack([0.01 * p[:, 0], -0.005 * p[:, 1] + 0.2])  # noqa: E731
    t = fit_table(X, lin(X), xn, yn, smoothing=1.0)
    corner = np.array([[95.0, -95.0]])
    assert np.abs(t(corner) - lin(corner)).max() < 1e-3      # linear fields extrapolate exactly


def test_folds_partition_the_points():
    f = folds(23, 5)
    assert sorted(np.concatenate(f).tolist()) == list(range(23)) and len(f) == 5


def test_too_few_points():
    X = grid(3, 50.0)
    with pytest.raises(CalibrationError, match="too few measured spots.*9.*10"):
        select_rbf(X, FIELD(X))


# -- iterated correction ------------------------------------------------------------------
def test_iterated_correction_lands_on_target():
    Q = np.random.default_rng(1).uniform(-95, 95, (300, 2))
    K = invert(FIELD, Q)
    landing = K + FIELD(K)
    assert np.abs(landing - Q).max() < 1e-4
    one_step = Q - FIELD(Q)                         # K = Q + δ̂ of the paper, not iterated
    assert np.abs(one_step + FIELD(one_step) - Q).max() > 1e-3


def test_iterated_correction_with_a_fitted_model(training):
    X, D, V = training
    net = select_rbf(X, D).model
    K = invert(net, V)
    assert np.abs(K + net(K) - V).max() < 1e-4
    assert rms(K + FIELD(K) - V) < 0.01


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.1, 3.0))
def test_iterated_correction_property(seed, rms_mm):
    field_ = PolynomialFieldDistortion.random(np.random.default_rng(seed), rms_mm=rms_mm)
    Q = np.random.default_rng(seed + 1).uniform(-90, 90, (50, 2))
    K = invert(field_, Q)
    assert np.abs(K + field_(K) - Q).max() < 1e-4


def test_folding_field_does_not_converge():
    fold = lambda p: np.column_stack([-2.0 * p[:, 0] + 0.01 * p[:, 0] ** 2,  # noqa: E731
                                      np.zeros(len(p))])
    with pytest.raises(CalibrationError, match="does not converge"):
        invert(fold, np.array([[50.0, 0.0], [-30.0, 0.0]]))


def test_area_table_rings_and_squares():
    pts = np.array([[0.0, 0.0], [50.0, 0.0], [0.0, -89.0]])
    dev = np.array([[0.1, 0.0], [0.0, 0.2], [0.3, 0.4]])
    rows = {r.name.split()[0] + (r.name.split()[1] if r.name.startswith("inner") else ""): r
            for r in area_table(pts, dev, 90.0)}
    assert rows["all"].n == 3 and rows["all"].max_mm[2] == pytest.approx(0.5)
    assert rows["centre"].n == 1 and rows["middle"].n == 1 and rows["edge"].n == 1
    assert rows["edge"].rms_mm == pytest.approx((0.3, 0.4, 0.5))


# -- file -----------------------------------------------------------------------------------
def _file_for(model, **kw) -> FieldCorrection:
    method = "rbf" if isinstance(model, RBFNetwork) else "table"
    return FieldCorrection(method=method, field_size_mm=[200.0, 200.0],
                           region_mm=[-90.0, 90.0, -90.0, 90.0], **model_spec(model), **kw)


@pytest.mark.parametrize("kind", ["rbf", "table"])
def test_file_round_trip(training, tmp_path, kind):
    X, D, V = training
    model = fit_rbf(X, D, 60.0, 1e-5) if kind == "rbf" else \
        fit_table(X, D, *table_nodes((-100, 100, -100, 100), X, 20.0), smoothing=0.01)
    fc = _file_for(model, commands_mm=X.tolist(), landed_mm=(X + D).tolist(),
                   residuals={"cv_rms_mm": 0.01})
    path = tmp_path / "field.json"
    save_field_correction(path, fc)
    back = load_field_correction(path)
    assert back.kind == "field-correction" and back.method == kind
    assert np.allclose(back.correct(V), fc.correct(V), atol=1e-12)
    assert np.allclose(correction_from_file(path)(V), invert(model, V), atol=1e-9)
    assert json.loads(path.read_text())["convention"].startswith("landing(C) = C + delta(C)")


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(kind="height-calibration"), "kind: expected 'field-correction'"),
    (lambda d: d.pop("rbf"), "rbf: missing"),
    (lambda d: d["rbf"]["weights_mm"].pop(), "rbf.weights_mm: expected 3 weights"),
    (lambda d: d["rbf"].update(sigma_mm=-1), "rbf.sigma_mm"),
    (lambda d: d.update(region_mm=[0, 1]), "region_mm: expected 4 numbers"),
    (lambda d: d.update(method="spline"), "method"),
])
def test_file_validation_names_the_field(tmp_path, change, message):
    net = RBFNetwork(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(2), 30.0)
    data = _file_for(net).model_dump(mode="json")
    change(data)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=message) as e:
        load_field_correction(path)
    assert str(path) in str(e.value) and "\n" not in str(e.value)


def test_table_file_validation(tmp_path):
    t = CorrectionTable(np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0]), np.zeros((2, 3, 2)))
    data = _file_for(t).model_dump(mode="json")
    data["table"]["x_nodes_mm"] = [0.0, 2.0, 1.0]
    path = tmp_path / "t.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="table.x_nodes_mm: expected strictly increasing"):
        load_field_correction(path)


def test_targets_and_commands_must_stay_in_the_field():
    shift = RBFNetwork(np.zeros((1, 2)), np.zeros((1, 2)), np.array([-3.0, 0.0]), 30.0)
    fc = _file_for(shift)                       # lands 3 mm to -x: commands go 3 mm to +x
    assert np.allclose(fc.correct(np.array([[10.0, 5.0]])), [[13.0, 5.0]])
    with pytest.raises(SafetyError, match=r"target 2: \[120, 0\] mm is outside the scan field"):
        fc.correct(np.array([[0.0, 0.0], [120.0, 0.0]]))
    with pytest.raises(SafetyError, match=r"target 1: \[99, 0\] mm needs the command \[102, 0\]"):
        fc.correct(np.array([[99.0, 0.0]]))


# -- use cases on a simulated recording -----------------------------------------------------
@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    """7 × 7 spots, binning 4 (a few of them outside the camera's view)."""
    out = tmp_path_factory.mktemp("field") / "rec"
    record_field_calibration(simulated(SimWorld(default_rig(3, binning=4), seed=3)), out, n=7)
    return out


@pytest.fixture(scope="module")
def correction(rec):
    return calibrate_field(rec, "rbf")


def test_measure_spots_on_the_plate(rec):
    seq = Sequence.open(rec)
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
def test_calibrate_field_reduces_the_deviation(rec, correction, method):
    fc = correction if method == "rbf" else calibrate_field(rec, "table")
    r = fc.residuals
    assert fc.method == method and r["points"] >= 35
    assert r["before_rms_mm"] > 0.7 and r["cv_rms_mm"] < 0.3 * r["before_rms_mm"]
    assert fc.areas_before[0].n == r["points"] and len(fc.after_mm) == r["points"]
    assert fc.region_mm[1] == pytest.approx(90.0)
    rig = default_rig(3, binning=4)
    Q = grid(6, 60.0)
    true_err = rig.beams.landing(fc.correct(Q)) - Q          # 7 × 7 is coarse; still ~5× better
    assert rms(true_err) < 0.25 * rms(rig.beams.landing(Q) - Q)


def test_plate_not_flat_is_refused(rec, tmp_path):
    bad = tmp_path / "rec"
    shutil.copytree(rec, bad)
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


def test_cli_calibrate_and_correct(rec, tmp_path):
    out = tmp_path / "FIELD.json"
    res = _run("calibrate", "field", rec, "-o", out)
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


def test_cli_bad_input(rec, tmp_path):
    out = tmp_path / "FIELD.json"
    _one_line_error(_run("calibrate", "field", tmp_path / "missing", "-o", out), "missing")
    _one_line_error(_run("calibrate", "field", rec, "-o", out, "--method", "magic"), "--method")
    hcal = Path(__file__).parents[1] / "data" / "height-cal-b4"
    _one_line_error(_run("calibrate", "field", hcal, "-o", out),
                    "a 'height-calibration' sequence, not a field calibration")
    assert not out.exists() and not out.with_suffix(".png").exists()

    res = _run("calibrate", "field", rec, "-o", out)
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
@pytest.fixture(scope="module")
def marked(tmp_path_factory):
    """Circles of 2 mm marked uncorrected on a 9 × 9 grid over ±80 mm, imaged (binning 2)."""
    out = tmp_path_factory.mktemp("marked") / "rec"
    record_marked_field_calibration(simulated(SimWorld(default_rig(3, binning=2), seed=3)), out, n=9,
                                    half_mm=80.0)
    return out


def test_marked_circles_are_found_where_the_beam_landed(marked):
    seq = Sequence.open(marked)
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


def test_marked_circles_calibrate_the_field(marked):
    cal = calibrate_field(marked, "rbf")
    assert cal.residuals["cv_rms_mm"] < 0.03 and cal.residuals["before_rms_mm"] > 0.5


def test_a_frame_without_marks_is_refused(marked, tmp_path):
    seq = Sequence.open(marked)
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
