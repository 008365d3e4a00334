"""A Mono12 camera's recording says its bits, and its scan measures as its 8-bit twin's."""

from __future__ import annotations

import numpy as np

from insitu.devices.protocols import pixel_bits_of
from insitu.formats.sequence import Sequence
from insitu.services import scan_replay
from insitu.services.record import record_scan
from insitu.services.station import simulated
from insitu.sim.world import sim_world


class Mono12:
    """The simulated camera as a Mono12 GenICam camera delivers it: uint16, 0 … 4095."""

    pixel_bits = 12

    def __init__(self, camera):
        self._camera = camera

    def __getattr__(self, name):
        return getattr(self._camera, name)

    def grab(self, timeout_s: float = 5.0) -> np.ndarray:
        img = self._camera.grab(timeout_s)
        return np.round(img.astype(np.float64) * 4095 / 255).astype(np.uint16)


def _scan(tmp_path, mono12: bool):
    station = simulated(sim_world("step-block", seed=0, binning=2))
    if mono12:
        station.devices.camera = Mono12(station.devices.camera)
    assert pixel_bits_of(station.devices.camera) == (12 if mono12 else None)
    out = record_scan(station, tmp_path / f"scan-{mono12}", spacing=4.0,
                      region=(-8, 8, -34, -26))
    return Sequence.open(out), scan_replay(out).cloud


def test_a_mono12_cameras_recording_says_its_bits_and_measures_as_8_bits(tmp_path):
    seq8, cloud8 = _scan(tmp_path, False)
    seq12, cloud12 = _scan(tmp_path, True)
    assert seq8.pixel_bits is None and seq12.pixel_bits == 12
    assert seq12.read_frame(0).dtype == np.uint16
    assert len(cloud8.points) > 100
    assert abs(len(cloud12.points) / len(cloud8.points) - 1) < 0.05
    assert abs(np.median(cloud12.points[:, 2]) - np.median(cloud8.points[:, 2])) < 0.005
