"""GRBL Z stage over a real pseudo-terminal against a thread that speaks GRBL."""

import threading

import pytest

from fakes.grbl import GrblPeer
from insitu.devices.protocols import Stage
from insitu.devices.stage_grbl import GrblStage, parse_status
from insitu.errors import DeviceError


@pytest.fixture
def peer():
    p = GrblPeer()
    yield p
    p.close()


def open_stage(peer, **kw):
    return GrblStage(peer.port, **{"timeout_s": 3.0, "poll_s": 0.01, "reply_timeout_s": 0.3, **kw})


def test_open_homes_and_moves_to_heights(peer):
    stage = open_stage(peer, offset_mm=-20.0, home_on_open=True)
    try:
        assert isinstance(stage, Stage)
        assert stage.version.startswith("Grbl 1.1")
        assert peer.lines[:2] == ["G21 G90", "$H"] and peer.realtime[0] == b"\x18"
        assert stage.position_z() == pytest.approx(-20.0)
        stage.move_z(-12.5)                       # machine z 7.5 mm at 200 mm/s
        assert peer.lines[-1] == "G1 Z7.5000 F300.0"
        assert peer.pos[2] == pytest.approx(7.5)
        assert stage.position_z() == pytest.approx(-12.5)
        stage.move_z(-19.0)
        assert stage.position_z() == pytest.approx(-19.0)
    finally:
        stage.close()


def test_out_of_range_is_refused_before_sending(peer):
    stage = open_stage(peer, z_range_mm=(0.0, 10.0))
    n = len(peer.lines)
    with pytest.raises(DeviceError, match=r"outside the stage range \[0, 10\] mm"):
        stage.move_z(11.0)
    assert len(peer.lines) == n
    stage.close()


def test_alarm_during_a_move_stops_with_a_clear_message(peer):
    peer.speed = 5.0                              # slow: the move takes 2 s
    stage = open_stage(peer)
    timer = threading.Timer(0.2, peer.alarm, args=(1,))
    timer.start()
    with pytest.raises(DeviceError, match="alarm 1: hard limit triggered|in alarm"):
        stage.move_z(10.0)
    timer.join()
    assert 0.0 < peer.pos[2] < 10.0
    with pytest.raises(DeviceError, match="locked out during alarm"):
        stage.move_z(2.0)
    stage.home()                                  # homing clears the alarm
    stage.move_z(1.0)
    assert stage.position_z() == pytest.approx(1.0)
    stage.close()


def test_stage_that_stops_answering_times_out(peer):
    stage = open_stage(peer)
    peer.silent = True
    with pytest.raises(DeviceError, match="no answer to 'G1 Z3.0000 F300.0'"):
        stage.move_z(3.0)
    stage.close()


def test_no_grbl_on_the_port_is_a_clear_error(tmp_path):
    with pytest.raises(DeviceError, match="cannot open"):
        GrblStage(str(tmp_path / "ttyNOPE"))
    p = GrblPeer()
    p.silent = True
    try:
        with pytest.raises(DeviceError, match="is a GRBL controller on this port"):
            GrblStage(p.port, reply_timeout_s=0.3)
    finally:
        p.close()


def test_status_reports_of_both_grbl_versions():
    assert parse_status("<Idle|MPos:1.000,2.000,-3.500|FS:0,0>") == (
        "Idle", {"MPos": [1.0, 2.0, -3.5], "FS": [0.0, 0.0]})
    state, f = parse_status("<Run,MPos:0.000,0.000,4.000,WPos:0.000,0.000,1.000>")
    assert state == "Run" and f["MPos"][2] == 4.0 and f["WPos"][2] == 1.0
    assert parse_status("<Hold:0|WPos:0,0,2|Bf:15,128>")[1]["WPos"] == [0.0, 0.0, 2.0]
    with pytest.raises(DeviceError, match="not a status report"):
        parse_status("ok")
