"""``insitu depth`` on a recorded scan: the simulated pocket plate recorded by ``insitu sim record
scan --workpiece pocket-plate`` (lines 0.1 mm apart over its 0.2 mm pocket, binning 4 to keep
it a few seconds), replayed with the depth scan's centres; the depth within 3σ (the σ the
command states) of truth.json's true mean depth."""

import json

import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from run_folders import shared


@pytest.fixture(scope="module")
def plate_scan(tmp_path_factory):
    def record(folder):
        run = CliRunner().invoke(app, ["sim", "record", "scan", "--workpiece", "pocket-plate",
                                       "--binning", "4", "--spacing", "0.1", "--region",
                                       "1.2", "3.8", "-2.2", "2.2", "-o", str(folder / "scan")])
        assert run.exit_code == 0, run.output
    return shared(tmp_path_factory, "pocket-plate-scan", record) / "scan"


def test_the_recorded_pocket_is_measured_to_the_truth_within_its_stated_sigma(
        plate_scan, tmp_path, monkeypatch):
    """Replayed with the depth scan's centres (across the line only) and the recording's
    camera and head as the viewpoints."""
    from insitu.services import depth as service

    seen, replay, measure = {}, service.scan_replay, service.measure_depth

    def spy_replay(*a, **kw):
        seen["centres"] = kw["centres"]
        return replay(*a, **kw)

    def spy_measure(*a, **kw):
        seen["viewpoints"] = kw["viewpoints"]
        return measure(*a, **kw)
    monkeypatch.setattr(service, "scan_replay", spy_replay)
    monkeypatch.setattr(service, "measure_depth", spy_measure)
    truth = json.loads((plate_scan / "truth.json").read_text())
    pocket = truth["pockets"][2]
    assert pocket["depth_mm"] == 0.2 and "rig" in truth and "region" in truth
    box = ",".join(f"{v:g}" for v in pocket["box"])
    run = CliRunner().invoke(app, ["depth", str(plate_scan), "--pocket", box,
                                   "-o", str(tmp_path / "report")])
    assert run.exit_code == 0, run.output
    (got,) = json.loads((tmp_path / "report" / "depth.json").read_text())["pockets"]
    assert got["floor_lines"] >= 8
    assert abs(got["depth_mm"] - pocket["true_mean_mm"]) <= 3 * got["sigma_mm"], got
    assert got["sigma_mm"] < 0.02
    c = seen["centres"]
    assert (c.method, c.smooth_half_window, c.smooth_grains) == ("gaussian", 0, 0.0)
    assert seen["viewpoints"].shape == (2, 3) and seen["viewpoints"][1, 2] > 100
