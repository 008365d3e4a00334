"""Height calibration (Li et al. §2.2 and ours) on the committed recordings."""

from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.calibrate.height_fit import LineObservation, fit_paper, fit_sheet
from insitu.cli.main import app
from insitu.errors import CalibrationError, MeasurementError
from insitu.formats.calibration import HeightCalibration
from insitu.formats.json_file import load_json_model
from insitu.formats.pointcloud import read_ply
from insitu.reconstruct.plate_models import SheetHeightModel
from insitu.services import load_height_calibration, scan_replay
from insitu.sim.workpieces import make_workpiece

DATA = Path(__file__).parents[1] / "data"
runner = CliRunner()


@pytest.fixture
def cal(height_cal):
    """tests/data/height-cal-b4 fitted (tests/conftest.py: once per run)."""
    return height_cal


def _step_height_errors(cloud):
    part = make_workpiece("step-block")
    p = cloud.points
    errs = []
    for y0, y1 in ((-40, -20), (-20, 0), (0, 20), (20, 40)):
        sel = (np.abs(p[:, 0]) < 8) & (p[:, 1] > y0 + 2) & (p[:, 1] < y1 - 2)
        errs.append(np.mean(p[sel, 2] - part.height(p[sel, 0], p[sel, 1])))
    return np.array(errs)


def test_calibration_has_both_models_and_residuals(cal):
    assert cal.model == "sheet" and cal.paper is not None
    r = cal.residuals
    assert r["sheet_rms_mm"] < r["paper_rms_mm"]          # ours fits the plate better
    assert 0 < r["sheet_cv_rms_mm"] < 0.3                 # binning 4: coarse pixels
    assert "7 heights" in cal.notes and "13 offsets" in cal.notes


def test_method2_beats_method1_on_the_step_block(cal):
    plane = _step_height_errors(scan_replay(DATA / "scan-step-block-b4").cloud)
    ours = _step_height_errors(scan_replay(DATA / "scan-step-block-b4", cal).cloud)
    paper = _step_height_errors(scan_replay(DATA / "scan-step-block-b4", cal, "paper").cloud)
    assert np.max(np.abs(ours)) < 0.05, ours
    assert np.max(np.abs(paper)) < 0.2, paper            # the paper: within ±0.2 mm
    assert np.max(np.abs(plane)) > 2 * np.max(np.abs(ours))


def test_sheet_model_recovers_a_synthetic_distorted_sheet():
    """Observations made from a known curved sheet family are fitted and inverted exactly."""
    from insitu.sim.rig import default_rig
    cam = default_rig(seed=1, binning=4).operator.camera
    H = 350.0

    def true_x(x, Y, Z):          # pivot model plus a smooth bend, like a distorted field
        return x * (H - Z) / H + 0.3 * (Y / 60) ** 2 + 0.002 * x * Z / 10 + 0.1 * x / 30

    obs = []
    for z in (-15.0, -5.0, 5.0, 15.0):
        for x in np.arange(-30.0, 31.0, 10.0):
            Y = np.linspace(-45, 45, 200)
            pts = np.column_stack([true_x(x, Y, z), Y, np.full_like(Y, z)])
            uv = cam.project(pts)
            obs.append(LineObservation(x, z, uv[:, 0], uv[:, 1]))
    model = fit_sheet(obs, cam, H)
    Y = np.linspace(-40, 40, 50)
    pts = np.column_stack([true_x(12.5, Y, 7.0), Y, np.full_like(Y, 7.0)])
    uv = cam.project(pts)
    np.testing.assert_allclose(model.points(cam, 12.5, uv[:, 0], uv[:, 1]), pts, atol=2e-3)
    restored = SheetHeightModel.from_dict(model.to_dict())
    np.testing.assert_allclose(restored.points(cam, 12.5, uv[:, 0], uv[:, 1]), pts, atol=2e-3)


def test_paper_model_needs_the_reference_line():
    obs = [LineObservation(5.0, 0.0, np.arange(10.0), np.arange(10.0))]
    with pytest.raises(CalibrationError, match="reference line"):
        fit_paper(obs)


def _top_errors(cloud, margin=1.0):
    """Height errors (N,) mm of the points over the step block's top at least ``margin`` mm
    from any wall (as benchmarks/accuracy.py scores them)."""
    part, p = make_workpiece("step-block"), cloud.points
    z = part.height(p[:, 0], p[:, 1])
    ok = np.isfinite(z)
    for dx, dy in ((margin, 0), (-margin, 0), (0, margin), (0, -margin)):
        zn = part.height(p[:, 0] + dx, p[:, 1] + dy)
        ok &= np.isfinite(zn) & (np.abs(zn - z) < 0.05 * margin + 0.3)
    return p[ok, 2] - z[ok]


def _rms_max(e):
    return float(np.sqrt(np.mean(e ** 2))), float(np.max(np.abs(e)))


# Accuracy regressions: bounds 1.5 × the figures measured when the tests were written.
def test_method2_accuracy_at_binning_2():
    """The step block at binning 2 (7 lines) with a height calibration fitted from a binning-2
    recording (tests/data/make_recordings.sh): RMS 0.0176, max 0.0808 mm today."""
    cal = load_height_calibration(DATA / "height-cal-b2.json")
    e = _top_errors(scan_replay(DATA / "scan-step-block-b2", cal).cloud)
    rms, worst = _rms_max(e)
    assert len(e) > 3000
    assert rms <= 1.5 * 0.0176 and worst <= 1.5 * 0.0808, (rms, worst)


def test_method2_accuracy_fitted_at_binning_4(cal):
    """The fit itself, on the committed binning-4 recordings: ours RMS 0.0675, max 0.205 mm;
    the paper's model 0.102 / 0.295 mm today."""
    for which, (rms0, max0) in (("sheet", (0.0675, 0.205)), ("paper", (0.102, 0.295))):
        rms, worst = _rms_max(_top_errors(scan_replay(DATA / "scan-step-block-b4", cal,
                                                      which).cloud))
        assert rms <= 1.5 * rms0 and worst <= 1.5 * max0, (which, rms, worst)


def test_cli_calibrate_then_scan_with_the_file(height_cal_file, tmp_path):
    """``insitu calibrate height``'s file (tests/conftest.py fits it with the command): its
    residuals, their grid and picture; scans measure with it."""
    hjson = height_cal_file
    cal = load_json_model(hjson, HeightCalibration)
    assert cal.residuals["sheet_rms_mm"] > 0 and cal.centres.method == "steger"
    # the residual grid: one cell per plate height × line offset, its RMS consistent with the
    # overall one, and drawn beside the file
    g = cal.residual_grid
    rms = np.array([[np.nan if v is None else v for v in row] for row in g.rms_mm])
    assert rms.shape == (len(g.heights_mm), len(g.offsets_mm)) and len(g.heights_mm) >= 3
    assert np.nanmin(rms) > 0 and np.nanmax(rms) <= cal.residuals["sheet_max_mm"]
    assert np.nanmax(rms) >= cal.residuals["sheet_rms_mm"] * 0.9
    picture = cv2.imread(str(hjson.with_suffix(".png")))
    assert picture is not None and picture.shape[1] >= 500
    out = tmp_path / "c.ply"
    res = runner.invoke(app, ["scan", "--replay", str(DATA / "scan-step-block-b4"),
                              "--height-cal", str(hjson), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "height (sheet)" in res.output
    assert np.max(np.abs(_step_height_errors(read_ply(out)))) < 0.05
    # the recorded folder works as HCAL too, and --method plane ignores it
    res = runner.invoke(app, ["scan", "--replay", str(DATA / "scan-step-block-b4"), "--height-cal",
                              str(DATA / "height-cal-b4"), "--method", "plane", "-o", str(out)])
    assert res.exit_code == 0 and "plane" in res.output


def test_height_calibration_from_another_rig_is_refused(height_cal_file, tmp_path):
    res = runner.invoke(app, ["scan", "--replay", str(DATA / "scan-step-block-full"),
                              "--height-cal", str(height_cal_file), "-o", str(tmp_path / "c.ply")])
    assert res.exit_code == 1
    assert "another rig" in res.output and "612×512" in res.output
    assert not (tmp_path / "c.ply").exists()


def test_heights_outside_the_calibration_are_refused(cal):
    narrow = cal.model_copy(deep=True)
    narrow.sheet.z_range_mm = [-15.0, 5.0]       # as if the plate had only gone up to 5 mm
    with pytest.raises(MeasurementError, match="outside the height calibration"):
        scan_replay(DATA / "scan-step-block-b4", narrow)


def test_a_few_stray_heights_are_dropped_more_are_refused(cal):
    """A ghost's short streak above the calibrated heights loses its points, not the scan;
    a part the calibration does not reach is refused."""
    from insitu.reconstruct.plate_models import STRAY, check_bracket
    from insitu.services.height import height_model

    model = height_model(cal)[1]
    lo, hi = model.z_range
    z = np.linspace(lo, hi, 10_000)
    z[:int(STRAY * len(z))] = hi + 3.0
    inside = check_bracket(model, z, "scan")
    assert (~inside).sum() == int(STRAY * len(z)) and inside[int(STRAY * len(z)):].all()
    z[:int(STRAY * len(z)) + 1] = hi + 3.0
    with pytest.raises(MeasurementError, match="outside the height calibration"):
        check_bracket(model, z, "scan")


def test_wrong_sequence_kind(tmp_path):
    res = runner.invoke(app, ["calibrate", "height", str(DATA / "scan-step-block-b4"),
                              "-o", str(tmp_path / "h.json")])
    assert res.exit_code == 1 and "not a height calibration" in res.output
    assert not (tmp_path / "h.json").exists()
