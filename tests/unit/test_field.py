"""Scan-field correction: the RBF network (OLS), the correction table, the iterated correction
and the file, on synthetic fields (on simulated recordings:
tests/integration/test_field_calibration.py)."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from insitu.calibrate.field import (
    CorrectionTable,
    RBFNetwork,
    fit_rbf,
    fit_table,
    folds,
    invert,
    ols_order,
    select_rbf,
    select_table,
    table_nodes,
)
from insitu.calibrate.field_areas import area_table
from insitu.calibrate.field_file import (
    FieldCorrection,
    correction_from_file,
    load_field_correction,
    model_spec,
    save_field_correction,
)
from insitu.errors import CalibrationError, ConfigError, SafetyError
from insitu.geometry.distortion import PolynomialFieldDistortion

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
