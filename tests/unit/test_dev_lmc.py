"""JCZ/LMC backend against a fake board behind a pyusb backend: the byte stream (single
commands, list packets), unit conversions, pilot preview, unplugging and the watchdog."""

import struct

import numpy as np
import pytest

from fakes.lmc_usb import FakeLmcBoard
from insitu.devices.galvo import Controller, joint_from_targets
from insitu.devices.lmc import LmcController, LmcSettings, packets
from insitu.errors import DeviceError, SafetyError
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import GalvoDriver, LaserParams, make_job, run_job, run_preview

HEAD = TwoMirrorHead(350.0, 12.0)
BITS_PER_DEG = 1500.0


def settings(**kw):
    return LmcSettings(**{"bits_per_deg": BITS_PER_DEG, "heartbeat_s": 30.0, **kw})


@pytest.fixture
def board():
    return FakeLmcBoard()


@pytest.fixture
def lmc(board):
    c = LmcController(HEAD, settings(), backend=board)
    yield c
    c.close()


def flat_job(n=2):
    paths = [np.array([[x, -4.0, 0.0], [x, 4.0, 0.0], [x + 1.0, 4.0, 0.0]])
             for x in np.linspace(-4, 4, n)]
    return make_job(paths, LaserParams(power_pct=30, frequency_khz=20, mark_speed_mm_s=500,
                                       jump_speed_mm_s=3000))


def singles(board, start=0):
    return [c[0] if not any(c[1:]) else c[:2] for c in board.singles[start:]]


def test_open_initialises_the_board(lmc, board):
    assert isinstance(lmc, Controller)
    assert singles(board) == [0x09, 0x07, 0x1F, 0x15, 0x04, 0x16, (0x1B, 1), (0x17, 1),
                              (0x1C, 1), 0x33, 0x21]
    assert all(len(w) == 12 for w in board.writes)


def test_no_board_is_a_clear_error(board):
    with pytest.raises(DeviceError, match=r"no board 1 on USB \(found 1 with id 9588:9899\)"):
        LmcController(HEAD, settings(index=1), backend=board)


def test_job_byte_stream_and_units(lmc, board):
    n0 = len(board.writes)
    job = flat_job()
    run_job(job, GalvoDriver(HEAD), lmc)
    stream = board.writes[n0:]
    lists = [w for w in stream if len(w) == 0xC00]
    assert len(lists) == 2                      # one packet per path
    first = [struct.unpack_from("<6H", lists[0], i) for i in range(0, 0xC00, 12)]
    assert first[0] == (0x8051, 0, 0, 0, 0, 0)  # ready-mark
    ops = {e[0]: e for e in first}
    assert ops[0x8007][1:3] == (100, 0) and ops[0x8008][1:3] == (150, 0)   # laser delays µs
    assert ops[0x800D][1:3] == (250, 0)                                   # jump delay µs
    units_per_mm = BITS_PER_DEG * np.degrees(1 / 700.0)
    assert ops[0x800C][1] == round(500 * units_per_mm / 1000)             # mark speed
    assert ops[0x8006][1] == round(3000 * units_per_mm / 1000)            # jump speed
    assert ops[0x8012][1] == 1228 and ops[0x801B][1] == 1000              # 30 %, 20 kHz
    assert ops[0x8004][1] == 15                                           # mark delay, 10 µs
    assert first[-1] == (0x8002, 0, 0, 0, 0, 0)                            # padding
    # every packet is followed by SetEndOfList, then ExecuteList; MO open only while marking
    after = [struct.unpack("<6H", w)[0] for w in stream[stream.index(lists[0]) + 1:][:2]]
    assert after == [0x19, 0x05]
    # what the board marked: the mirror angles × bits_per_deg around 0x8000
    want = []
    for p in job.paths:
        g = np.rint(joint_from_targets(HEAD, p.points)[:, :2] * BITS_PER_DEG) + 0x8000
        want += [(*g[i], *g[i + 1]) for i in range(len(g) - 1)]
    assert [m[1:] for m in board.marks] == [tuple(map(int, w)) for w in want]
    assert not board.laser_output() and board.mo == 0 and board.port == 0


def test_long_lists_stream_in_packets(lmc, board):
    path = np.column_stack([np.linspace(-5, 5, 800), np.zeros(800), np.zeros(800)])
    n0 = len(board.writes)
    run_job(make_job([path]), GalvoDriver(HEAD), lmc)
    kinds = ["L" if len(w) == 0xC00 else struct.unpack("<6H", w)[0] for w in board.writes[n0:]]
    lists = [i for i, k in enumerate(kinds) if k == "L"]
    assert len(lists) == 4
    assert kinds.index(0x05) == lists[2] + 2    # executes after the third packet, streams on
    assert len(board.marks) == 799


def test_packets_are_padded_to_0xc00():
    ps = packets([(0x8001, 1, 2, 0, 0, 0)] * 300)
    assert [len(p) for p in ps] == [0xC00, 0xC00]
    assert struct.unpack_from("<6H", ps[1], 43 * 12) == (0x8001, 1, 2, 0, 0, 0)
    assert struct.unpack_from("<6H", ps[1], 44 * 12) == (0x8002, 0, 0, 0, 0, 0)


def test_pilot_preview_lights_without_the_laser(lmc, board):
    run_preview(flat_job(), GalvoDriver(HEAD), lmc, outline="bbox")
    lists = [w for w in board.writes if len(w) == 0xC00]
    entries = [struct.unpack_from("<6H", w, i) for w in lists for i in range(0, 0xC00, 12)]
    assert (0x8011, 1 << 8, 0, 0, 0, 0) in entries and (0x8011, 0, 0, 0, 0, 0) in entries
    assert board.marks == [] and board.mo == 0


def test_focus_shift_beyond_the_tolerance_is_refused_before_sending(lmc, board):
    n0 = len(board.writes)
    job = make_job([np.array([[0.0, 0.0, 3.0], [1.0, 0.0, 3.0]])])
    with pytest.raises(SafetyError, match="no dynamic focus"):
        run_job(job, GalvoDriver(HEAD), lmc)
    assert all(len(w) == 12 for w in board.writes[n0:])     # laser-off commands only
    assert board.marks == []


def test_unplugged_mid_list(lmc, board):
    board.step = 1
    board.unplug_after(12)
    with pytest.raises(DeviceError, match="board unplugged"):
        run_job(flat_job(3), GalvoDriver(HEAD), lmc)
    assert board.unplugged and not board.laser_output()
    n = board.transfers
    with pytest.raises(DeviceError, match="no heartbeat"):
        run_job(flat_job(3), GalvoDriver(HEAD), lmc)
    assert board.transfers - n <= 4             # only the laser-off attempts


def test_watchdog_notices_an_idle_board_unplugged(board):
    import time
    lmc = LmcController(HEAD, settings(heartbeat_s=0.05), backend=board)
    try:
        board.unplug_after(0)
        t_end = time.monotonic() + 3
        while lmc.heartbeat.alive and time.monotonic() < t_end:
            time.sleep(0.02)
        assert not lmc.heartbeat.alive
        with pytest.raises(DeviceError, match="no heartbeat from the controller"):
            lmc.execute(GalvoDriver(HEAD).compile(flat_job(1))[0])
    finally:
        lmc.close()


def test_the_abortable_service_marks_with_the_laser_on(lmc, board):
    """The GUI marks through services.mark with a cancel event: each path still reaches the
    board as one list, so the board switches the laser on for it (sent one command at a time,
    no list held laser_on and nothing was marked)."""
    import threading

    from insitu.services.mark import mark

    result = mark(flat_job(), GalvoDriver(HEAD), lmc, None, cancel=threading.Event())
    assert result.state == "done"
    assert len(board.marks) == 4            # the fake records a mark only with the laser on
    assert not board.laser_output() and board.mo == 0 and board.port == 0


def test_a_job_whose_last_path_needs_focus_sends_nothing(lmc, board, tmp_path):
    n0 = len(board.writes)
    job = make_job([np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
                    np.array([[2.0, 0.0, 0.0], [3.0, 0.0, 0.0]]),
                    np.array([[0.0, 0.0, 3.0], [1.0, 0.0, 3.0]])])
    with pytest.raises(SafetyError, match="no dynamic focus"):
        run_job(job, GalvoDriver(HEAD), lmc, tmp_path / "job.progress.json")
    assert all(len(w) == 12 for w in board.writes[n0:])     # no list packet
    assert board.runs == 0 and board.marks == []
    assert not (tmp_path / "job.journal.jsonl").exists()


def test_a_cut_path_on_the_lmc_cannot_be_continued(lmc, board, tmp_path):
    from insitu.marking import history
    job, prog = flat_job(3), tmp_path / "job.progress.json"
    board.unplug_after(40)
    with pytest.raises(DeviceError):
        run_job(job, GalvoDriver(HEAD), lmc, prog)
    s = history(job, prog)
    assert s.cut is not None and s.cut_position is None        # the board reports no position
    ok = LmcController(HEAD, settings(), backend=FakeLmcBoard())
    try:
        with pytest.raises(SafetyError, match="did not report how far path"):
            run_job(job, GalvoDriver(HEAD), ok, prog, resume=True, cut_path="continue")
        assert run_job(job, GalvoDriver(HEAD), ok, prog, resume=True,
                       cut_path="remark").state == "done"
    finally:
        ok.close()
