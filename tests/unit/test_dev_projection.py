"""Line projection for scanning on a real head (here the fake LMC board behind pyusb): the
line is drawn repeatedly at pilot power until it changes, and a fault stops it, laser off."""

import json
import struct
import time

import numpy as np
import pytest

from fakes.lmc_usb import FakeLmcBoard
from insitu.devices.galvo import nominal_commands
from insitu.devices.lmc import LmcController, LmcSettings
from insitu.devices.projection import GalvoLineProjector
from insitu.devices.protocols import ScanHead
from insitu.errors import DeviceError, SafetyError
from insitu.geometry.beams import TwoMirrorHead

HEAD = TwoMirrorHead(350.0, 12.0)


@pytest.fixture
def board():
    return FakeLmcBoard()


def projector(board, **kw):
    lmc = LmcController(HEAD, LmcSettings(bits_per_deg=1500.0, heartbeat_s=30.0), board,
                        poll_s=0.0)
    return GalvoLineProjector(lmc, HEAD, (200.0, 200.0), (-25.0, 25.0), **kw)


def list_entries(board):
    return [struct.unpack_from("<6H", w, i) for w in board.writes if len(w) == 0xC00
            for i in range(0, 0xC00, 12)]


def test_pilot_line_is_redrawn_until_changed_then_off(board):
    head = projector(board, sweeps=2)
    assert isinstance(head, ScanHead)
    head.show_line(np.array([-10.0, -20.0]), np.array([-10.0, 20.0]))
    runs = board.runs
    time.sleep(0.2)
    assert board.runs > runs                        # still being drawn
    head.show_line(np.array([5.0, -20.0]), np.array([5.0, 20.0]))
    head.off()
    entries = list_entries(board)
    assert (0x8011, 1 << 8, 0, 0, 0, 0) in entries   # pilot on …
    assert board.marks == [] and board.port == 0 and board.mo == 0   # … never the laser
    # the last line drawn: mirror angles for x = 5 mm, y = ±20 mm on z = 0
    marks = [e for e in entries if e[0] == 0x8005]
    ax = (np.array([m[1] for m in marks[-4:]]) - 0x8000) / 1500.0
    ay = (np.array([m[2] for m in marks[-4:]]) - 0x8000) / 1500.0
    q = nominal_commands(HEAD, np.column_stack([ax, ay, np.zeros(4)]))
    np.testing.assert_allclose(q[:, 0], 5.0, atol=0.01)
    np.testing.assert_allclose(sorted(q[:2, 1]), [-20.0, 20.0], atol=0.01)
    head.controller.close()


def test_marking_laser_at_pilot_power(board):
    head = projector(board, source="laser", power_pct=0.5, frequency_khz=80.0, sweeps=1)
    head.show_line(np.array([0.0, -5.0]), np.array([0.0, 5.0]))
    head.off()
    assert (0x8012, 20, 0, 0, 0, 0) in list_entries(board)         # 0.5 % of 0xFFF
    assert len(board.marks) >= 2 and not board.laser_output()
    head.controller.close()


def test_line_speed_sets_the_sweep_speed(board):
    head = projector(board, sweeps=1)
    head.set_line_speed(750.0)
    assert [c.args for c in head.sweep_list(np.array([0.0, -5.0]), np.array([0.0, 5.0]))
            if c.op == "set_mark_speed"] == [(750.0,)]
    with pytest.raises(SafetyError, match="line speed 0 mm/s"):
        head.set_line_speed(0.0)
    head.controller.close()


def test_outside_the_field_is_refused(board):
    head = projector(board)
    with pytest.raises(SafetyError, match="outside the field"):
        head.show_line(np.array([0.0, -150.0]), np.array([0.0, 0.0]))
    head.controller.close()


def test_marking_laser_that_would_mark_is_refused(board):
    """1 % of 20 W at 20 kHz puts 1.0 J/cm² in a 50 µm spot's pulse: beech (0.7 J/cm²)
    would be marked; at 80 kHz and 0.5 % a pulse carries 0.13 J/cm², under 0.25 × 0.7."""
    with pytest.raises(SafetyError, match=r"beech.*power_pct ≤ 0\.17"):
        projector(board, source="laser", power_pct=1.0)
    assert board.marks == [] and not board.laser_output()


def test_the_stations_own_materials_file_sets_the_limit(board, tmp_path):
    """A station whose materials file holds paper (0.1 J/cm²): 0.5 % at 80 kHz (0.13 J/cm² a
    pulse) would mark it."""
    table = {"format": "insitu-materials/1", "laser": {"power_w": 20, "spot_um": 50},
             "materials": [{"name": "paper", "threshold_j_cm2": 0.1, "penetration_um": 5,
                            "pen": {"name": "engrave-paper", "power_pct": 5}}]}
    path = tmp_path / "materials.json"
    path.write_text(json.dumps(table))
    with pytest.raises(SafetyError, match=r"paper.*power_pct ≤ 0\.0"):
        projector(board, source="laser", power_pct=0.5, frequency_khz=80.0,
                  materials_file=path)
    assert board.marks == [] and not board.laser_output()


def test_fault_while_projecting_stops_it_laser_off(board):
    head = projector(board, source="laser", power_pct=0.5, frequency_khz=80.0)
    head.show_line(np.array([0.0, -5.0]), np.array([0.0, 5.0]))
    board.unplug_after(30)
    time.sleep(0.3)
    with pytest.raises(DeviceError, match="line projection stopped: .*unplugged"):
        head.show_line(np.array([1.0, -5.0]), np.array([1.0, 5.0]))
    assert not board.laser_output()
    head.off()
    head.controller.close()
