"""A packed recording keeps the laser-off frames of its packed exposures, and its replay
subtracts them as the live scan does."""

from __future__ import annotations

import json

import numpy as np

from insitu.formats.sequence import Sequence
from insitu.services.record import record_scan
from insitu.services.scan import scan_replay
from insitu.services.scan_frames import recorded_excess
from insitu.services.station import simulated
from insitu.sim.world import sim_world


def test_a_packed_recording_keeps_its_laser_off_frames_and_its_replay_uses_them(tmp_path):
    """`sim record scan --lines-per-frame 3` writes one laser-off frame per packed exposure
    (``laser_off``); the replay subtracts (K − 1)/K of it from those frames, as the live scan
    does: without them in sequence.json the same frames give other centres."""
    out = tmp_path / "rec"
    record_scan(simulated(sim_world("step-block", seed=3, binning=4)), out, 2.0,
                (-4.0, 4.0, -30.0, 30.0), lines_per_frame=3)
    seq = Sequence.open(out)
    packed = {f.exposure_ms for f in seq.frames if len(f.drawn()) > 1 and not f.survey}
    assert {f.exposure_ms for f in seq.laser_off} == packed and len(packed) >= 1
    assert set(recorded_excess(seq)) == {len(f.drawn()) for f in seq.frames
                                         if len(f.drawn()) > 1 and not f.survey}
    with_off = scan_replay(out).cloud.points
    data = json.loads((out / "sequence.json").read_text())
    del data["laser_off"]
    (out / "sequence.json").write_text(json.dumps(data))
    without = scan_replay(out).cloud.points
    assert len(with_off) > 50
    assert len(with_off) != len(without) or not np.allclose(with_off, without)
