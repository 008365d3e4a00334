"""On a real station (opt-in): ``INSITU_RIG=/path/rig.json pytest -m hardware``. Pilot laser
only; nothing is marked. Deselected everywhere else (pyproject's addopts: -m "not hardware")."""

import os
from pathlib import Path

import numpy as np
import pytest

from insitu.services.station import connect

RIG = os.environ.get("INSITU_RIG")
pytestmark = pytest.mark.hardware


@pytest.fixture(scope="module")
def station():
    assert RIG, "set INSITU_RIG to a real station's rig file"
    with connect(Path(RIG)) as s:
        yield s.devices


def test_camera_sees_the_pilot_line(station):
    dark = station.camera.grab().astype(float)
    station.head.show_line(np.array([0.0, -20.0]), np.array([0.0, 20.0]))
    lit = station.camera.grab().astype(float)
    station.head.off()
    assert dark.shape == lit.shape == (station.camera.height, station.camera.width)
    assert lit.max() > dark.max() or (lit - dark).sum() > 0


def test_stage_moves_and_reads_back(station):
    assert station.stage is not None, "this rig file names no stage"
    z0 = station.stage.position_z()
    station.stage.move_z(z0 + 1.0)
    assert station.stage.position_z() == pytest.approx(z0 + 1.0, abs=0.01)
    station.stage.move_z(z0)
