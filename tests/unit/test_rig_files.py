"""Calibration and rig configuration files: round trip and one-line errors naming file and field."""

from __future__ import annotations

import json
from datetime import datetime, timezone

import numpy as np
import pytest

from insitu.errors import ConfigError, FormatError
from insitu.formats.calibration import CameraCalibration
from insitu.formats.json_file import CalibrationEnvelope, load_json_model, save_json_model
from insitu.formats.rig import RigConfig, ScanHeadConfig, ScanHeadGeometry
from insitu.formats.sequence import ScanHeadSpec

CAMERA = {"width": 64, "height": 48, "K": [[60.0, 0, 32.0], [0, 60.0, 24.0], [0, 0, 1]],
          "dist": [0.01, -0.02, 0.0, 0.0, 0.0], "R": np.eye(3), "t": [0.0, 0.0, 300.0]}


def _camera_cal() -> CameraCalibration:
    return CameraCalibration(camera=CAMERA, rms_px=0.21, per_view_rms_px=[0.2, 0.22],
                             std_intrinsics=[0.5, 0.5, 0.3, 0.3], inputs=["rec/cam"],
                             residuals={"rms_px": 0.21}, notes="sim")


def _head() -> ScanHeadConfig:
    return ScanHeadConfig(pivot_height_mm=350.0, mirror_distance_mm=350.0,
                          mirror_separation_mm=12.0, field_size_mm=[200.0, 200.0],
                          z_range_mm=[-25.0, 25.0])


def test_camera_calibration_round_trip(tmp_path):
    cal = _camera_cal()
    save_json_model(tmp_path / "camera.json", cal)
    back = load_json_model(tmp_path / "camera.json", CameraCalibration)
    assert back == cal and back.path == tmp_path / "camera.json"
    np.testing.assert_array_equal(back.camera.R_array, np.eye(3))
    data = json.loads((tmp_path / "camera.json").read_text())
    assert data["schema_version"] == 1 and data["kind"] == "camera" and data["units"] == "mm"
    created = datetime.fromisoformat(data["created"])
    assert created.tzinfo is not None and created.utcoffset().total_seconds() == 0
    assert abs((datetime.now(timezone.utc) - created).total_seconds()) < 60
    assert [p.name for p in tmp_path.iterdir()] == ["camera.json"]    # no temp file left


def test_scan_head_config_round_trip(tmp_path):
    head = _head()
    assert head.kind == "scan-head" and head.lens == "non-telecentric"
    save_json_model(tmp_path / "head.json", head)
    back = load_json_model(tmp_path / "head.json", ScanHeadConfig)
    assert back == head
    assert ScanHeadSpec(**back.spec()) == ScanHeadSpec(
        lens="non-telecentric", pivot_height_mm=350.0, field_size_mm=[200.0, 200.0],
        z_range_mm=[-25.0, 25.0])
    assert back.spec(mirrors=True)["mirror_distance_mm"] == 350.0
    # the file is a geometry (one type): it drives the head as it is, or reduced to just that
    assert isinstance(back, ScanHeadGeometry) and back.geometry() == ScanHeadGeometry(
        **back.spec(mirrors=True))


def test_extra_fields_of_calibrations_are_kept(tmp_path):
    (tmp_path / "c.json").write_text(json.dumps({**_camera_cal().model_dump(mode="json"),
                                                 "solver": {"iterations": 12}}))
    cal = load_json_model(tmp_path / "c.json", CameraCalibration)
    assert cal.model_extra == {"solver": {"iterations": 12}}
    assert load_json_model(tmp_path / "c.json", CalibrationEnvelope).kind == "camera"


def test_rig_config_round_trip_and_resolve(tmp_path):
    (tmp_path / "calib").mkdir()
    rig = RigConfig(camera="replay", stage="none", camera_calibration="calib/camera.json",
                    scan_head_config=str(tmp_path / "abs.json"), sim_seed=4,
                    options={"replay": {"folder": "rec"}})
    save_json_model(tmp_path / "rig.json", rig)
    back = load_json_model(tmp_path / "rig.json", RigConfig)
    assert back.model_dump() == rig.model_dump()
    assert back.resolve(back.camera_calibration) == tmp_path / "calib" / "camera.json"
    assert back.resolve(back.scan_head_config) == tmp_path / "abs.json"
    assert back.resolve(back.height_calibration) is None
    assert RigConfig().camera == "sim" and RigConfig().scan_head == "sim"


def test_wrong_kind(tmp_path):
    (tmp_path / "x.json").write_text(json.dumps({"kind": "field-correction", "grid": []}))
    with pytest.raises(ConfigError) as info:
        load_json_model(tmp_path / "x.json", CameraCalibration)
    assert str(info.value) == f"{tmp_path / 'x.json'}: kind: expected 'camera', got 'field-correction'"
    save_json_model(tmp_path / "head.json", _head())
    with pytest.raises(ConfigError, match="head.json: kind: expected 'camera', got 'scan-head'"):
        load_json_model(tmp_path / "head.json", CameraCalibration)


@pytest.mark.parametrize("drop, words", [
    (("camera",), ["camera: missing (required)"]),
    (("camera", "K"), ["camera.K: missing (required)"]),
])
def test_missing_field_is_named(tmp_path, drop, words):
    data = _camera_cal().model_dump(mode="json")
    node = data
    for key in drop[:-1]:
        node = node[key]
    del node[drop[-1]]
    (tmp_path / "c.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError) as info:
        load_json_model(tmp_path / "c.json", CameraCalibration)
    for word in words:
        assert word in str(info.value) and str(info.value).startswith(str(tmp_path / "c.json"))


@pytest.mark.parametrize("change, words", [
    (lambda d: d.pop("mirror_distance_mm"), ["mirror_distance_mm: missing"]),
    (lambda d: d.update(mirror_separation_mm=-1), ["mirror_separation_mm: -1 is outside 0 … 200 mm"]),
    (lambda d: d.update(lens="fisheye"), ["lens: expected 'non-telecentric' or 'telecentric'"]),
    (lambda d: d.update(z_range_mm=[1, 1]), ["z_range_mm: expected [low, high] with low < high"]),
    (lambda d: d.update(field_size_mm=[200]), ["field_size_mm: expected 2 numbers, got [200]"]),
    (lambda d: d.update(created="yesterday"), ["created: expected an ISO-8601 time"]),
    (lambda d: d.update(residuals={"rms": "high"}), ["residuals.rms: expected a number"]),
    (lambda d: d.update(schema_version=0), ["schema_version: expected 1 to 1"]),
])
def test_bad_scan_head_config(tmp_path, change, words):
    data = _head().model_dump(mode="json")
    change(data)
    (tmp_path / "h.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError) as info:
        load_json_model(tmp_path / "h.json", ScanHeadConfig)
    assert "\n" not in str(info.value)
    for word in words:
        assert word in str(info.value), str(info.value)


def test_newer_schema_version(tmp_path):
    data = {**_head().model_dump(mode="json"), "schema_version": 7, "new_thing": 1}
    (tmp_path / "h.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="h.json: schema_version 7 is newer .* update insitu"):
        load_json_model(tmp_path / "h.json", ScanHeadConfig)


def test_rig_config_refuses_typos_and_unknown_backends(tmp_path):
    (tmp_path / "rig.json").write_text(json.dumps({"camera_calibraton": "calib/c.json"}))
    with pytest.raises(ConfigError, match="rig.json: camera_calibraton: not a known field"):
        load_json_model(tmp_path / "rig.json", RigConfig)
    (tmp_path / "rig.json").write_text(json.dumps({"scan_head": "galvo9000"}))
    with pytest.raises(ConfigError, match="scan_head: expected 'sim', 'rtc' or 'lmc', got 'galvo9000'"):
        load_json_model(tmp_path / "rig.json", RigConfig)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(FormatError, match="nope.json: file not found"):
        load_json_model(tmp_path / "nope.json", RigConfig)
    (tmp_path / "bad.json").write_text('{"camera": "sim",}')
    with pytest.raises(FormatError, match=r"bad.json: not valid JSON \(line 1, column 18"):
        load_json_model(tmp_path / "bad.json", RigConfig)
    (tmp_path / "list.json").write_text("[]")
    with pytest.raises(ConfigError, match="list.json: expected a JSON object, got"):
        load_json_model(tmp_path / "list.json", RigConfig)
    with pytest.raises(FormatError, match="does not exist"):
        save_json_model(tmp_path / "no" / "rig.json", RigConfig())


def test_height_calibration_of_version_1_reads_as_it_was_made(tmp_path):
    """A version-1 height calibration left out the centre settings added after it: they are
    read as it was extracted (no smoothing by grains, the paper's threshold, no carried ends),
    not as a new calibration's defaults, and the file is written back whole as version 2."""
    from pathlib import Path

    from insitu.formats.calibration import HeightCalibration
    from insitu.vision.extract import CentreSettings

    data = json.loads((Path(__file__).parents[1] / "data" / "height-cal-b2.json").read_text())
    data["schema_version"] = 1
    for key in ("smooth_grains", "background", "extend_ends", "end_fraction"):
        data["centres"].pop(key, None)
    (tmp_path / "old.json").write_text(json.dumps(data))
    cal = load_json_model(tmp_path / "old.json", HeightCalibration)
    assert cal.schema_version == 2
    c = cal.centres
    assert (c.smooth_grains, c.background, c.extend_ends, c.end_fraction) == (0.0, False, False,
                                                                              0.5)
    new = CentreSettings()
    assert (new.smooth_grains, new.background, new.extend_ends) != (0.0, False, False)
    save_json_model(tmp_path / "new.json", cal)
    again = json.loads((tmp_path / "new.json").read_text())
    assert again["schema_version"] == 2 and again["centres"]["background"] is False
    del again["centres"]["background"]          # a version-2 file must say it
    (tmp_path / "bad.json").write_text(json.dumps(again))
    with pytest.raises(ConfigError, match="bad.json: centres.background"):
        load_json_model(tmp_path / "bad.json", HeightCalibration)
