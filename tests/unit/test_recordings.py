"""The committed recordings (tests/data, made by make_recordings.sh) replay through the same
code path as live frames."""

from pathlib import Path

import numpy as np
import pytest

from insitu.devices.replay import ReplayCamera
from insitu.errors import DeviceError
from insitu.formats.sequence import Sequence
from insitu.services import scan_replay
from insitu.services.station import simulated
from insitu.sim.workpieces import make_workpiece

DATA = Path(__file__).parents[1] / "data"


def _step_errors(cloud, tol_edge=1.5):
    """Median height error per step top, mm (truth from the step block's height function)."""
    part = make_workpiece("step-block")
    p = cloud.points
    out = []
    for y0, y1 in ((-40, -20), (-20, 0), (0, 20), (20, 40)):
        sel = (np.abs(p[:, 0]) < 10 - tol_edge) & (p[:, 1] > y0 + tol_edge) & (p[:, 1] < y1 - tol_edge)
        out.append(np.median(p[sel, 2] - part.height(p[sel, 0], p[sel, 1])))
    return np.array(out)


@pytest.mark.parametrize("name, frames, size", [
    ("scan-step-block-b4", 27, (612, 512)),
    ("scan-step-block-full", 3, (2448, 2048)),
    ("height-cal-b4", 91, (612, 512)),
])
def test_recordings_are_valid(name, frames, size):
    seq = Sequence.open(DATA / name)
    assert len(seq) == frames
    assert (seq.camera.width, seq.camera.height) == size
    assert seq.read_frame(0).shape == size[::-1]


@pytest.mark.parametrize("name", ["scan-step-block-b4", "scan-step-block-full"])
def test_recorded_scan_reconstructs_the_step_block(name):
    result = scan_replay(DATA / name)
    assert result.summary.frames_with_line >= 0.9 * result.summary.frames
    err = _step_errors(result.cloud)
    assert np.all(np.abs(err) < 1.5), err        # Method 1 with the operator's calibration


def test_replay_camera_serves_frames_in_order_then_stops():
    seq = Sequence.open(DATA / "scan-step-block-b4")
    cam = ReplayCamera(seq)
    first = cam.grab()
    assert cam.current.line.start[0] == seq.frames[0].line.start[0]
    np.testing.assert_array_equal(first, seq.read_frame(0))
    for _ in range(len(seq) - 1):
        cam.grab()
    with pytest.raises(DeviceError, match="no frame 27"):
        cam.grab()


def test_lines_running_down_the_image_are_searched_across():
    """A camera mounted turned by 90°: the lines run along the image columns."""
    from dataclasses import replace

    from insitu.geometry.camera import CameraModel, rotation_about
    from insitu.services import scan_live
    from insitu.sim.world import sim_world

    world = sim_world("step-block", seed=2, binning=4)
    Rz = rotation_about([0, 0, 1], np.pi / 2)

    def turned(cam):
        K = cam.K.copy()
        K[0, 2], K[1, 2] = cam.height - 1 - cam.K[1, 2], cam.K[0, 2]
        return CameraModel(cam.height, cam.width, K, cam.dist, Rz @ cam.R, Rz @ cam.t)

    rig = world.rig
    world.rig = replace(rig, camera=turned(rig.camera),
                        operator=replace(rig.operator, camera=turned(rig.operator.camera)))
    result = scan_live(simulated(world), spacing=2.0)
    assert result.summary.frames_with_line >= 0.9 * result.summary.frames
    err = _step_errors(result.cloud)
    assert np.all(np.abs(err) < 1.5), err
