"""SCANLAB RTC backend against a fake RTC library compiled from C at test time: the ctypes
signatures, the unit conversions, the list protocol, faults and the heartbeat watchdog."""

import time

import numpy as np
import pytest

from fakes.rtc import FakeBoard, build
from fakes.station import allow
from insitu.devices.galvo import Command, Controller, joint_from_targets
from insitu.devices.rtc import RtcController, RtcSettings
from insitu.errors import ConfigError, DeviceError, SafetyError
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import GalvoDriver, LaserOverride, LaserParams, make_job, run_job, run_preview

HEAD = TwoMirrorHead(350.0, 12.0)
K = 2000.0


@pytest.fixture(scope="module")
def lib_path(tmp_path_factory):
    return allow(build(tmp_path_factory.mktemp("rtc")))   # the station allows the fake


@pytest.fixture
def board(lib_path):
    b = FakeBoard(lib_path)
    b.reset()
    return b


def settings(lib_path, tmp_path, **kw):
    cor = tmp_path / "head3d.ct5"
    cor.write_bytes(b"\0" * 64)
    base = dict(library=lib_path, correction_file=cor, k_bits_per_mm=K, kz_bits_per_mm=1000.0,
                generation=6, heartbeat_s=30.0)
    return RtcSettings(**{**base, **kw})


@pytest.fixture
def rtc(lib_path, tmp_path, board):
    c = RtcController(HEAD, settings(lib_path, tmp_path))
    yield c
    c.close()


def small_job():
    return make_job([np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 5.0, 1.0]]),
                     np.array([[-5.0, -5.0, 2.0], [-5.0, 5.0, 2.0]])],
                    LaserParams(power_pct=30, frequency_khz=20, mark_speed_mm_s=500,
                                jump_speed_mm_s=3000), {1: LaserOverride(power_pct=50.0)})


def test_open_initialises_the_board_and_loads_the_correction_file(rtc, board, lib_path):
    assert isinstance(rtc, Controller)
    calls = board.calls()
    cor = str(rtc.s.correction_file)
    assert calls[:10] == ["init_rtc6_dll", "select_rtc 1", "stop_execution",
                          f"load_program_file {lib_path.parent}",
                          f"load_correction_file {cor} 1 3", "select_cor_table 1 0",
                          "set_laser_mode 1", "set_laser_control 0", "disable_laser",
                          "write_io_port_mask 0 1"]
    assert calls[10] == "get_last_error"


def test_rtc5_library(lib_path, tmp_path, board):
    RtcController(HEAD, settings(lib_path, tmp_path, generation=5)).close()
    calls = board.calls()
    assert calls[0] == "init_rtc5_dll" and calls[-1] == "free_rtc5_dll"


def test_bad_library_or_correction_file_is_a_clear_error(lib_path, tmp_path, board):
    with pytest.raises(DeviceError, match="cannot load the library"):
        RtcController(HEAD, settings(tmp_path / "nope.so", tmp_path))
    s = settings(lib_path, tmp_path)
    with pytest.raises(DeviceError, match="correction file .*missing.ct5: cannot load it"):
        RtcController(HEAD, RtcSettings(**{**s.__dict__,
                                           "correction_file": tmp_path / "missing.ct5"}))
    with pytest.raises(ConfigError, match="generation: expected 5 or 6"):
        RtcController(HEAD, settings(lib_path, tmp_path, generation=4))


def test_job_units_reach_the_board_in_bits(rtc, board):
    board.reset()
    job = small_job()
    assert run_job(job, GalvoDriver(HEAD), rtc).state == "done"
    calls = board.calls()
    # speeds mm/s → bits/ms, delays µs → ½ µs and 10 µs, 20 kHz → 25 µs = 1600 × 1/64 µs,
    # power 30 % and 50 % of 4095
    assert "set_jump_speed 6000.000000" in calls and "set_mark_speed 1000.000000" in calls
    assert "set_laser_delays 200 300" in calls
    assert "set_laser_pulses 1600 128" in calls
    assert "write_da_1_list 1228" in calls and "write_da_1_list 2048" in calls
    sc = [c for c in calls if c.startswith("set_scanner_delays")]
    assert sc[0].startswith("set_scanner_delays 25 15 ")   # jump 250 µs, mark 150 µs
    assert calls.count("execute_list 1") == 2 and calls.count("enable_laser") == 2
    assert calls[-3:] == ["stop_execution", "disable_laser", "write_io_port_mask 0 1"]
    # what the board marked is the job, in bits (x, y × 2000/mm, z × 1000/mm)
    m = board.marks()
    scale = np.array([K, K, 1000.0])
    want = [np.array([[0, 0, 0], [10, 0, 0]]), np.array([[10, 0, 0], [10, 5, 1]]),
            np.array([[-5, -5, 2], [-5, 5, 2]])]
    assert len(m) == 3
    for row, seg in zip(m, want):
        np.testing.assert_allclose(row[1:4], seg[0] * scale, atol=1.0)
        np.testing.assert_allclose(row[4:7], seg[1] * scale, atol=1.0)
    assert not board.laser_enabled and board.port == 0


def test_pilot_preview_never_enables_the_laser(rtc, board):
    board.reset()
    run_preview(small_job(), GalvoDriver(HEAD), rtc, outline="bbox")
    calls = board.calls()
    assert "enable_laser" not in calls
    assert calls.count("write_io_port_mask_list 1 1") == 1
    assert calls.count("write_io_port_mask_list 0 1") == 1
    assert len(board.marks()) == 0 and board.port == 0


def test_out_of_range_is_refused_before_the_list(rtc, board):
    board.reset()
    far = joint_from_targets(HEAD, np.array([[300.0, 0.0, 0.0]]))[0]
    cmd = Command("jump_abs_3d", tuple(map(float, far)))
    with pytest.raises(SafetyError, match="outside the board's"):
        rtc.execute([cmd])
    assert "set_start_list 1" not in board.calls()


def test_board_that_stops_answering_mid_list(rtc, board):
    board.reset()
    board.set_step(1)
    board.fail_after(40)            # inside the first path's execution
    with pytest.raises(DeviceError, match="board does not respond"):
        run_job(small_job(), GalvoDriver(HEAD), rtc)
    calls = board.calls()
    assert board.dead and not board.laser_enabled
    assert calls[-3:] == ["!stop_execution", "!disable_laser", "!write_io_port_mask 0 1"]
    n = len(calls)
    with pytest.raises(DeviceError, match="no heartbeat"):
        rtc.execute([Command("laser_on"), Command("mark_abs_3d", (0.1, 0.0, 0.0))])
    assert not any("set_start_list" in c or "enable_laser" in c for c in board.calls()[n:])


def test_list_that_never_ends_times_out(lib_path, tmp_path, board):
    rtc = RtcController(HEAD, settings(lib_path, tmp_path, timeout_s=0.05))
    try:
        board.reset()
        board.set_step(1)
        job = make_job([np.array([[x, 0.0, 0.0], [x, 1.0, 0.0]]) for x in range(40)])
        t0 = time.monotonic()
        with pytest.raises(DeviceError, match="did not finish within 0.05 s"):
            rtc.execute(GalvoDriver(HEAD).compile(job)[0] * 30)
        assert time.monotonic() - t0 < 2.0
        assert board.calls()[-2:] == ["disable_laser", "write_io_port_mask 0 1"]
    finally:
        rtc.close()


def test_watchdog_turns_the_laser_off_when_the_idle_board_dies(lib_path, tmp_path, board):
    rtc = RtcController(HEAD, settings(lib_path, tmp_path, heartbeat_s=0.05))
    try:
        assert rtc.heartbeat.alive
        board.fail_after(0)
        deadline = time.monotonic() + 3.0
        while rtc.heartbeat.alive and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not rtc.heartbeat.alive
        assert "!disable_laser" in board.calls()
        n = len(board.calls())
        with pytest.raises(DeviceError, match="no heartbeat from the controller"):
            rtc.execute([Command("jump_abs_3d", (0.0, 0.0, 0.0))])
        assert not any("set_start_list" in c for c in board.calls()[n:])
    finally:
        rtc.close()


def test_a_job_whose_last_path_is_out_of_the_bit_range_sends_nothing(lib_path, tmp_path, board):
    """At 10,000 bits/mm the board reaches ±52 mm: the driver's field passes x = 80 mm, the
    board's check of the whole job refuses it before path 0 is sent."""
    rtc = RtcController(HEAD, settings(lib_path, tmp_path, k_bits_per_mm=1e4, kz_bits_per_mm=1e4))
    try:
        board.reset()
        job = make_job([np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]]),
                        np.array([[10.0, 0.0, 0.0], [80.0, 0.0, 0.0]])])
        with pytest.raises(SafetyError, match="outside the board's"):
            run_job(job, GalvoDriver(HEAD), rtc, tmp_path / "job.progress.json")
        assert not any(c.startswith(("set_start_list", "execute_list", "enable_laser"))
                       for c in board.calls())
        assert board.marks().size == 0 and not (tmp_path / "job.journal.jsonl").exists()
    finally:
        rtc.close()


def test_the_list_pointer_says_how_far_a_cut_path_got(rtc, board, tmp_path):
    job = make_job([np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]]),
                    np.column_stack([np.linspace(-5, 5, 12), np.zeros(12), np.zeros(12)])])
    board.reset()
    board.set_step(1)
    run_job(job, GalvoDriver(HEAD), rtc)
    start = [i for i, c in enumerate(board.calls()) if c == "execute_list 1"][1]
    board.reset()
    board.set_step(1)
    board.fail_after(start + 12)                    # some polls into path 1's execution
    with pytest.raises(DeviceError):
        run_job(job, GalvoDriver(HEAD), rtc, tmp_path / "job.progress.json")
    from insitu.marking import history
    s = history(job, tmp_path / "job.progress.json")
    assert s.done == {0} and s.cut == 1 and s.cut_position is not None
    marked_in_path_1 = sum(int(r[0]) == 2 for r in board.marks())
    assert 0 < s.cut_position <= marked_in_path_1, (s.cut_position, marked_in_path_1)


def test_pens_set_the_boards_delays_and_wobble_per_list(rtc, board):
    """Each path's pen reaches the board: its delays, its passes marked, its wobble with
    set_wobbel (circle: amplitude across and along, bits; Hz), off again for a list
    without."""
    from insitu.formats.pens import Delays, Pen, Wobble
    from insitu.marking import LaserOverride

    pen = Pen(name="p", passes=2, delays_us=Delays(laser_on=60.0, jump=400.0),
              wobble=Wobble(amplitude_mm=0.1, frequency_hz=800.0))
    path = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    job = make_job([path, path + [0, 5, 0]], overrides={0: LaserOverride.of_pen(pen)})
    board.reset()
    assert run_job(job, GalvoDriver(HEAD), rtc).state == "done"
    calls = board.calls()
    first, second = calls.index("execute_list 1"), len(calls)
    assert "set_wobbel 200 200 800.000" in calls[:first]
    assert "set_laser_delays 120 300" in calls[:first]               # 60 µs, 150 µs in ½ µs
    assert any(c.startswith("set_scanner_delays 40 15 ") for c in calls[:first])
    assert "set_wobbel 0 0 0.000" in calls[first:second]            # path 2: no wobble
    assert len(board.marks()) == 2 + 1                               # 2 passes, then path 2
