"""A whole station from a rig file — OpenCV camera (a recorded scan's frames as an image
sequence), RTC head (the fake library), GRBL stage (a pty peer) — and scans that meet a
device fault: the laser goes off, the scan stops with a clear message and keeps what it
measured."""

import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from fakes.grbl import GrblPeer
from fakes.rtc import FakeBoard, build
from fakes.station import allow
from insitu.errors import ConfigError
from insitu.formats.calibration import CameraCalibration
from insitu.formats.json_file import load_json_model, save_json_model
from insitu.formats.rig import RigConfig, ScanHeadConfig
from insitu.formats.sequence import Sequence
from insitu.services import ScanInterrupted
from insitu.services.scan import scan_live, scan_replay
from insitu.services.station import connect

PROGRESS = re.compile(r"[\w ]+: \d+ of \d+( \w+)?")   # a plain progress line (no terminal)

RECORDED = Path(__file__).parents[1] / "data" / "scan-step-block-b4"
REGION = tuple(json.loads((RECORDED / "truth.json").read_text())["region"])


@pytest.fixture(scope="module")
def rtc_lib(tmp_path_factory):
    return allow(build(tmp_path_factory.mktemp("rtc")))   # the station allows the fake


@pytest.fixture
def peer():
    p = GrblPeer()
    yield p
    p.close()


def write_rig(folder: Path, lib: Path, port: str, frames: int, **options) -> Path:
    seq = Sequence.open(RECORDED)
    save_json_model(folder / "camera.json", CameraCalibration(camera=seq.camera))
    save_json_model(folder / "head.json", ScanHeadConfig(
        pivot_height_mm=350.0, mirror_distance_mm=350.0, mirror_separation_mm=12.0,
        field_size_mm=(200.0, 200.0), z_range_mm=(-25.0, 25.0)))
    (folder / "frames").mkdir()
    # the camera's first frame: the room light, laser off (two frames' minimum: no line in it)
    cv2.imwrite(str(folder / "frames" / "00000.png"),
                np.minimum(seq.read_frame(0), seq.read_frame(len(seq) - 1)))
    for i, f in enumerate(sorted((RECORDED / "frames").glob("*.png"))[:frames], start=1):
        shutil.copy(f, folder / "frames" / f"{i:05d}.png")
    (folder / "head3d.ct5").write_bytes(b"\0" * 16)
    opts = {"camera": {"source": "frames/%05d.png", "timeout_s": 2.0},
            "rtc": {"library": str(lib), "correction_file": "head3d.ct5",
                    "k_bits_per_mm": 2000.0, "heartbeat_s": 30.0},
            "projection": {"sweeps": 2},
            "stage": {"port": port, "reply_timeout_s": 0.5, "timeout_s": 3.0}}
    for block, extra in options.items():
        opts[block] = {**opts.get(block, {}), **extra}
    rig = folder / "rig.json"
    rig.write_text(json.dumps({"kind": "rig", "camera": "opencv", "scan_head": "rtc",
                               "stage": "grbl", "camera_calibration": "camera.json",
                               "scan_head_config": "head.json", "options": opts}))
    return rig


def open_rig(rig: Path):
    """The station of ``rig``, its devices opened."""
    station = connect(rig)
    assert station.devices is not None                  # opened on first use
    return station


def test_station_scan_stops_when_the_camera_stops_delivering(tmp_path, rtc_lib, peer):
    board = FakeBoard(rtc_lib)
    board.reset()
    station = open_rig(write_rig(tmp_path, rtc_lib, peer.port, frames=15))
    try:
        assert station.world is None            # a real rig: nothing is simulated
        stage = station.devices.stage
        stage.move_z(4.0)
        assert stage.position_z() == pytest.approx(4.0)
        with pytest.raises(ScanInterrupted, match=r"scan stopped at line 16 of 27, laser off: "
                                                  r".*gave no frame") as err:
            scan_live(station, spacing=1.0, region=REGION)
        partial = err.value.partial
        assert partial is not None and partial.summary.frames == 15
        assert partial.summary.points > 1000
        assert partial.cloud.points[:, 0].max() < REGION[0] + 14 * 1.0 + 1.0
        # the head swept 16 lines with the pilot, and everything is off now
        calls = board.calls()
        assert calls.count("write_io_port_mask_list 1 1") >= 16
        assert "enable_laser" not in calls
        assert not board.laser_enabled and board.port == 0
    finally:
        station.close()


def test_station_scan_stops_when_the_scan_head_stops_answering(tmp_path, rtc_lib, peer):
    board = FakeBoard(rtc_lib)
    board.reset()
    station = open_rig(write_rig(tmp_path, rtc_lib, peer.port, frames=27))
    try:
        board.fail_after(400)
        with pytest.raises(ScanInterrupted, match="board does not respond") as err:
            scan_live(station, spacing=1.0, region=REGION)
        assert 0 < err.value.partial.summary.frames < 27
        assert board.dead and not board.laser_enabled
        assert board.calls()[-1] == "!write_io_port_mask 0 1"
    finally:
        station.close()


def test_rig_file_mistakes_are_clear(tmp_path, rtc_lib, peer):
    FakeBoard(rtc_lib).reset()
    rig = write_rig(tmp_path, rtc_lib, peer.port, frames=1, rtc={"k_bits": 1})
    with pytest.raises(ConfigError, match=r"options.rtc.k_bits: unknown; expected one of "):
        open_rig(rig)
    data = json.loads(rig.read_text())
    del data["camera_calibration"]
    rig.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="camera_calibration: required with a real camera"):
        connect(rig)
    data["camera_calibration"] = "camera.json"
    data["options"]["rtc"].pop("k_bits")
    data["options"]["camera"] = {}
    rig.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="options.camera.source: required"):
        open_rig(rig)
    assert np.isfinite(load_json_model(rig, RigConfig).options["rtc"]["k_bits_per_mm"])


def test_the_scan_command_keeps_what_it_measured_when_the_camera_stops(tmp_path, rtc_lib, peer):
    from typer.testing import CliRunner

    from insitu.cli.main import app
    from insitu.formats.pointcloud import read_ply

    FakeBoard(rtc_lib).reset()
    rig = write_rig(tmp_path, rtc_lib, peer.port, frames=15)
    out = tmp_path / "c.ply"
    res = CliRunner().invoke(app, ["scan", "-o", str(out), "--rig", str(rig), "--spacing", "1",
                                   "--region", *map(str, REGION)])
    assert res.exit_code == 1
    line = [ln for ln in res.output.splitlines() if ln.strip() and not PROGRESS.fullmatch(ln)]
    assert len(line) == 1 and "scan stopped at line 16 of 27, laser off" in line[0], res.output
    partial = tmp_path / "c.partial.ply"
    assert not out.exists() and str(partial) in res.output.replace("\n", "")
    assert len(read_ply(partial)) > 1000
    assert not FakeBoard(rtc_lib).laser_enabled


def test_a_real_rig_never_simulates_and_scans_only_where_it_is_told(tmp_path, rtc_lib, peer,
                                                                     monkeypatch):
    from typer.testing import CliRunner

    import insitu.sim.world as sim_world_module
    from insitu.cli.main import app

    def no_world(*a, **k):
        raise AssertionError("a real rig built a simulated world")

    monkeypatch.setattr(sim_world_module, "sim_world", no_world)
    monkeypatch.setattr(sim_world_module, "SimWorld", no_world)
    FakeBoard(rtc_lib).reset()
    rig = write_rig(tmp_path, rtc_lib, peer.port, frames=3)
    with connect(rig) as station:
        assert station.world is None and station.truth() is None
        result = scan_live(station, spacing=1.0, region=(REGION[0], REGION[0] + 2) + REGION[2:])
        assert result.summary.frames == 3
    out = tmp_path / "c.ply"
    res = CliRunner().invoke(app, ["scan", "-o", str(out), "--rig", str(rig)])
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert "--region: a scan on a real rig needs one (X0 X1 Y0 Y1, mm)" in lines[0]
    assert not out.exists() and not FakeBoard(rtc_lib).laser_enabled


def test_a_real_rig_records_a_scan_that_replays_like_a_live_one(tmp_path, rtc_lib, peer):
    from typer.testing import CliRunner

    from insitu.cli.main import app

    FakeBoard(rtc_lib).reset()
    rig = write_rig(tmp_path, rtc_lib, peer.port, frames=27)
    rec = tmp_path / "rec"
    res = CliRunner().invoke(app, ["record", "scan", "-o", str(rec), "--rig", str(rig),
                                   "--spacing", "1", "--region", *map(str, REGION)])
    assert res.exit_code == 0, res.output
    seq = Sequence.open(rec)
    assert len(seq) == 27 and not seq.has_truth          # a real rig knows no truth
    assert seq.frames[3].line.start == [REGION[0] + 3.0, REGION[2]]
    assert not FakeBoard(rtc_lib).laser_enabled
    replayed = scan_replay(rec)
    with connect(rig) as station:                         # the camera serves the same frames
        live = scan_live(station, spacing=1.0, region=REGION)
    assert replayed.summary.points == live.summary.points > 1000
    np.testing.assert_allclose(replayed.cloud.points, live.cloud.points)
    # a calibration on the plate needs a stage: this rig has one, a rig without is refused
    data = json.loads(rig.read_text())
    data["stage"] = "none"
    rig.write_text(json.dumps(data))
    res = CliRunner().invoke(app, ["record", "height-calibration", "-o", str(tmp_path / "h"),
                                   "--rig", str(rig)])
    assert res.exit_code == 1 and "needs the rig's Z stage" in res.output
    assert not (tmp_path / "h").exists()
