"""Each frame of a scan read in a window of one size over its own line's band, moved between
frames: a turned part's short lines are no longer read out over every line's rows."""

import numpy as np

from insitu.reconstruct.packing import Frame
from insitu.reconstruct.plan import scan_lines
from insitu.services.scan import reconstructor
from insitu.services.scan_frames import Shots, line_boxes, moving_window, region_of_interest
from insitu.sim.devices import SimCamera
from insitu.sim.rig import NOMINAL_HEAD, default_rig
from insitu.sim.world import sim_world


def _frames(lines):
    return [Frame((line,), (k,)) for k, line in enumerate(lines)]


def test_each_frame_is_read_in_a_window_of_one_size_over_its_own_line():
    rig = default_rig(seed=0, binning=4)
    cam = rig.operator.camera
    rec = reconstructor(cam, NOMINAL_HEAD.pivot_height_mm, False, (0.0, 16.0), None, None,
                        "test")
    # a part turned 45°: lines 0.5 mm apart, each over the part's width only
    lines = [(np.array([x, -x - 12.0]), np.array([x, -x + 12.0])) for x in
             np.arange(-30.0, 30.0, 0.5)]
    windows = moving_window(rec, _frames(lines), cam.width, cam.height)
    sizes = {(u1 - u0, v1 - v0) for u0, v0, u1, v1 in windows}
    assert len(sizes) == 1                                          # one size: no restart
    for (u0, v0, u1, v1), box in zip(windows, line_boxes(rec, lines)):
        assert u0 <= box[0] and v0 <= box[1] and box[2] <= u1 and box[3] <= v1
        assert 0 <= u0 and 0 <= v0 and u1 <= cam.width and v1 <= cam.height
    whole = region_of_interest(rec, lines)
    (cols, rows), = sizes
    assert rows * cols < 0.5 * (whole[2] - whole[0]) * (whole[3] - whole[1])


class _Head:
    def show_line(self, start, end, focus_z=0.0):
        pass

    def off(self):
        pass


def test_the_camera_follows_the_windows_and_a_move_costs_a_register_write():
    world = sim_world("step-block", seed=0, binning=4)
    camera = SimCamera(world)
    shot = Shots(camera, _Head(), (0, 0, 64, 64))
    lines = scan_lines((-1.0, 1.0, -5.0, 5.0), 1.0)
    windows = [(16 * k, 0, 16 * k + 32, 32) for k in range(len(lines))]
    seen = []
    camera.grab = lambda: seen.append(camera.roi) or np.zeros((camera.height, camera.width))
    shot.follow(windows)
    before = world.clock.now()
    for i, f in enumerate(_frames(lines)):
        shot.take(f, i, len(lines), lambda: None)
    assert seen == windows
    moves = (world.clock.now() - before).seconds
    assert moves == len(lines[1:]) * world.timing.roi_move_ms * 1e-3    # the first: a resize
    shot.done()
    assert camera.roi is None
