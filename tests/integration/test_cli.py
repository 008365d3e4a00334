"""The headless commands end to end on small simulated recordings."""

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.pointcloud import read_ply
from insitu.formats.sequence import Sequence

runner = CliRunner()
DATA = Path(__file__).parents[1] / "data"


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_sim_record_writes_a_valid_sequence_with_truth(scan_recording):
    seq = Sequence.open(scan_recording)
    assert seq.kind == "scan" and len(seq) > 5
    assert seq.has_truth
    truth = seq.read_truth()
    assert truth["workpieces"][0]["name"] == "step-block"
    # the sequence carries the operator's calibration, which differs from the truth
    assert not np.allclose(seq.camera.K_array, np.array(truth["rig"]["camera"]["K"]))


def test_scan_replay_writes_cloud_and_summary(scan_recording, tmp_path):
    out = tmp_path / "cloud.ply"
    res = _run("scan", "--replay", scan_recording, "-o", out)
    assert res.exit_code == 0, res.output
    assert "points" in res.output
    cloud = read_ply(out)
    assert len(cloud) > 500
    assert set(cloud.attributes) >= {"line", "intensity", "quality"}
    z = cloud.points[:, 2]
    on_block = (np.abs(cloud.points[:, 0]) < 8) & (cloud.points[:, 1] > 22) & (cloud.points[:, 1] < 38)
    assert abs(np.median(z[on_block]) - 15.0) < 2.5     # Method 1: right to a millimetre or two


def test_scan_live_on_the_simulated_rig(tmp_path):
    out = tmp_path / "live.ply"
    res = _run("scan", "-o", out, "--workpiece", "insert", "--binning", 4, "--spacing", 1.0)
    assert res.exit_code == 0, res.output
    assert len(read_ply(out)) > 100


@pytest.mark.parametrize("args, message", [
    (("scan", "--replay", "{tmp}/missing", "-o", "{tmp}/c.ply"), "missing"),
    (("scan", "-o", "{tmp}/nofolder/c.ply"), "does not exist"),
    (("scan", "-o", "{tmp}/c.txt"), ".ply"),
    (("scan", "-o", "{tmp}/c.ply", "--region", 0, 300, -10, 10), "outside the scan field"),
    (("scan", "-o", "{tmp}/c.ply", "--method", "magic"), "--method"),
    (("scan", "-o", "{tmp}/c.ply", "--line-speed", 0), "--line-speed: 0 is outside 0.1 … 20000 mm/s"),
    (("sim", "record", "bogus", "-o", "{tmp}/r"), "KIND"),
    (("scan", "-o", "{tmp}/c.ply", "--workpiece", "{tmp}/nothing.stl"), "nothing.stl"),
])
def test_bad_input_one_line_error_and_no_file(tmp_path, args, message):
    args = [str(a).format(tmp=tmp_path) for a in args]
    res = runner.invoke(app, args)
    assert res.exit_code != 0
    assert message in res.output
    assert isinstance(res.exception, SystemExit), res.exception    # not an uncaught error
    assert not (tmp_path / "c.ply").exists() and not list(tmp_path.glob(".*"))


def test_rig_file_drives_the_simulated_rig_with_its_calibration(tmp_path):
    res = _run("sim", "calib", "-o", tmp_path / "calib")
    assert res.exit_code == 0, res.output
    rig = tmp_path / "calib" / "rig.json"
    out = tmp_path / "c.ply"
    res = _run("scan", "-o", out, "--rig", rig, "--region", -2, 2, -45, 45, "--spacing", 2)
    assert res.exit_code == 0, res.output
    assert len(read_ply(out)) > 1000
    # a calibration for another camera size is refused, naming the file
    res = _run("scan", "-o", tmp_path / "d.ply", "--rig", rig, "--binning", 4)
    assert res.exit_code == 1 and "camera.json" in res.output
    # a real camera is opened as the rig file says (never probed): without its options, the
    # missing field is named
    rig.write_text(rig.read_text().replace('"camera": "sim"', '"camera": "genicam"'))
    res = _run("scan", "-o", tmp_path / "d.ply", "--rig", rig)
    assert res.exit_code == 1 and "options.camera.producer: required" in res.output
    assert not (tmp_path / "d.ply").exists()


def test_scan_preview_picture(scan_recording, tmp_path):
    res = _run("scan", "--replay", scan_recording, "-o", tmp_path / "c.ply", "--preview", tmp_path / "c.png")
    assert res.exit_code == 0, res.output
    import cv2
    img = cv2.imread(str(tmp_path / "c.png"))
    assert img is not None and (img < 250).any()


def test_a_rig_file_measures_with_the_height_calibration_it_names(height_cal_file, tmp_path):
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps({"kind": "rig", "sim_seed": 11,
                               "height_calibration": str(height_cal_file)}))
    res = _run("scan", "-o", tmp_path / "c.ply", "--rig", rig, "--binning", 4,
               "--region", -2, 2, -45, 45, "--spacing", 2)
    assert res.exit_code == 0, res.output
    assert "height (sheet)" in res.output
    res = _run("scan", "-o", tmp_path / "d.ply", "--rig", rig, "--binning", 4,
               "--region", -2, 2, -45, 45, "--spacing", 2, "--method", "plane")
    assert res.exit_code == 0 and "plane" in res.output
