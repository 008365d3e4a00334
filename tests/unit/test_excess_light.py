"""A frame of K lines holds K exposures of room light: a laser-off frame of its exposure is
taken before it and (K − 1)/K of its texture subtracted, so each line's centres see the room
light's texture of one line's exposure, as in a frame of its own (at the level of K)."""

from __future__ import annotations

import numpy as np

from insitu.reconstruct.bands import Band
from insitu.reconstruct.packing import Frame
from insitu.reconstruct.scan import excess_room_light, less_room_light
from insitu.services.scan_frames import Shots, laser_off_frames
from insitu.vision.band_centres import centres_in_bands

W, H, K = 160, 80, 4


def _room(exposures: float) -> np.ndarray:
    """(H, W) float: textured room light (a bright patch's edge beside the line, as a part's
    texture or shading gives) over ``exposures`` single-line exposures."""
    v = np.arange(H, dtype=np.float64)[:, None]
    return exposures * (12.0 + 10.0 * (v > 41.0)) * np.ones((1, W))


def _stripe() -> np.ndarray:
    v = np.arange(H, dtype=np.float64)[:, None]
    return 60.0 * np.exp(-0.5 * ((v - 40.0) / 1.5) ** 2) * np.ones((1, W))


def _u8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.round(x), 0, 255).astype(np.uint8)


def test_excess_is_k_minus_one_kth_rounded_less_its_level_where_read():
    """(K − 1)/K of the laser-off frame, rounded, less its median over the pixels read (> 0),
    split into what to take and what to give; nothing where none was read (outside the
    camera's window); applied with saturation at 0 and the frame's full scale."""
    off = np.array([[0, 1, 2, 3, 255]], np.uint8)
    got = excess_room_light(off, 4)                    # 1, 2, 2, 191 read: median 2
    assert got.split.dtype == np.uint8 and got.level == 2.0
    assert got.split.tolist() == [[[0, 0, 0, 0, 189]], [[0, 1, 0, 0, 0]]]
    deep = excess_room_light(np.array([[4095, 3000, 0]], np.uint16), 3)
    assert deep.split.dtype == np.uint16 and deep.level == 2365.0   # 2730 and 2000
    assert deep.split.tolist() == [[[365, 0, 0]], [[0, 365, 0]]]
    frame = np.array([[10, 4000, 4095]], np.uint16)
    assert less_room_light(frame, deep, 4095).tolist() == [[0, 4095, 4095]]
    assert less_room_light(frame, deep).tolist() == [[0, 4365, 4095]]


def test_the_excess_room_light_is_what_biases_a_packed_line():
    """One line's stripe beside a room-light edge: alone in its frame it is measured with
    one exposure's edge; in a frame of K lines the edge is K times as strong and pulls the
    centre off; less the excess, the centre is where the frame of its own puts it."""
    band = Band(np.full(W, 30.0), np.full(W, 50.0), True, 1)
    alone = centres_in_bands(_u8(_stripe() + _room(1)), [band])[0]
    packed_image = _u8(_stripe() + _room(K))
    packed = centres_in_bands(packed_image, [band])[0]
    less = less_room_light(packed_image, excess_room_light(_u8(_room(K)), K))
    fixed = centres_in_bands(less, [band])[0]
    bias_alone = abs(np.median(alone.v) - 40.0)
    bias_packed = abs(np.median(packed.v) - 40.0)
    bias_fixed = abs(np.median(fixed.v) - 40.0)
    assert bias_packed > 3 * bias_alone + 0.01, (bias_alone, bias_packed)
    assert bias_fixed < bias_alone + 0.01, (bias_alone, bias_fixed)


def test_a_packed_peak_stands_the_floor_above_the_level_kept():
    """A stripe of 25 DN over one exposure's room light (10 DN) stays under the detector's
    floor (40 DN) in a frame of its own; over four exposures' level it would pass it. With
    the level the packed frame keeps (30 DN) it gives no centre, as alone; a brighter one
    (60 DN) is kept either way."""
    band = Band(np.full(W, 30.0), np.full(W, 50.0), True, 1)
    flat = np.full((H, W), 10.0)
    for height, kept in ((25.0, False), (60.0, True)):
        stripe = _stripe() * height / 60.0
        alone = centres_in_bands(_u8(stripe + flat), [band])[0]
        packed = _u8(stripe + K * flat)
        excess = excess_room_light(_u8(K * flat), K)
        assert excess.level == 30.0
        left = centres_in_bands(less_room_light(packed, excess), [band], level=excess.level)[0]
        assert (len(alone) > W // 2) == kept and (len(left) > W // 2) == kept, (height, len(left))
        assert len(centres_in_bands(packed, [band])[0]) > W // 2   # on the level: passes


class _Camera:
    """Records each grab's exposure and whether the laser was on."""

    def __init__(self, head):
        self.exposure_ms, self.head, self.grabs = 10.0, head, []
        self.width, self.height = W, H

    def set_exposure(self, exposure_ms: float) -> None:
        self.exposure_ms = exposure_ms

    def grab(self, timeout_s: float = 5.0) -> np.ndarray:
        self.grabs.append((self.exposure_ms, self.head.on))
        return np.full((H, W), 40, np.uint8)


class _Head:
    field_size_mm, z_range_mm = (200.0, 200.0), (-25.0, 25.0)
    on = False

    def show_line(self, start, end, focus_z=0.0):
        self.on = True

    def show_lines(self, lines, focus_z=0.0):
        self.on = True

    def off(self):
        self.on = False


def test_one_laser_off_frame_for_each_exposure_of_several_lines():
    head = _Head()
    camera = _Camera(head)
    line = (np.zeros(2), np.ones(2))
    frames = [Frame((line,) * 4, (0, 1, 2, 3)), Frame((line,) * 4, (4, 5, 6, 7)),
              Frame((line,) * 3, (8, 9, 10)), Frame((line,), (11,)),
              Frame((line,) * 2, (12, 13), survey=True)]
    head.on = True
    got = laser_off_frames(Shots(camera, head, None), frames)
    assert sorted(got) == [3, 4] and int(got[4][0, 0]) == 40
    assert camera.grabs == [(30.0, False), (40.0, False)]
