"""Several lines per exposure: each centre on the one line whose band holds it, none where two
bands could hold it, and frames of `lines` written and read as formats.md says."""

from __future__ import annotations

import json

import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats.sequence import Sequence
from insitu.formats.sequence_writer import SequenceWriter
from insitu.reconstruct.bands import Band, Packing, exclusive
from insitu.reconstruct.scan import ScanReconstructor
from insitu.vision.band_centres import centres_in_bands

W, H = 200, 100


def _stripe(rows: np.ndarray) -> np.ndarray:
    """(H, W) uint8: a bright line of 1.5 px sigma at ``rows`` (W,) over a dim background."""
    v = np.arange(H, dtype=np.float64)[:, None]
    img = 12.0 + 200.0 * np.exp(-0.5 * ((v - rows[None, :]) / 1.5) ** 2)
    return np.clip(img, 0, 255).astype(np.uint8)


def test_a_column_two_bands_could_hold_gives_no_point():
    """Band B reaches into band A in columns 0–99 (rows 45–50): a stripe there, at row 47,
    is on neither line; in columns 100–199 the bands lie apart and it is A's."""
    lo_b = np.where(np.arange(W) < 100, 45.0, 55.0)
    a = Band(np.full(W, 30.0), np.full(W, 50.0), True, 1)
    b = Band(lo_b, np.full(W, 70.0), True, 1)
    image = _stripe(np.full(W, 47.0))
    ca, cb = centres_in_bands(image, exclusive([a, b], guard_px=1.0))
    assert len(cb) == 0
    assert len(ca) > 80 and ca.u.min() >= 100 and np.allclose(ca.v, 47.0, atol=0.05)
    # the same frame with the bands taken as they are (not made exclusive): both lines claim it
    ca, cb = centres_in_bands(image, [a, b])
    assert (ca.u < 100).any() and (cb.u < 100).any()


@pytest.fixture(scope="module")
def step_frame():
    """One simulated exposure (binning 4) of three lines 8 mm apart over the step block (the
    table, then steps 3, 5, 10 and 15 mm high along each line) and the world that drew it."""
    from insitu.services.station import simulated
    from insitu.sim.world import sim_world

    world = sim_world("step-block", seed=11, binning=4)
    station = simulated(world)
    lines = [(np.array([x, -46.0]), np.array([x, 46.0])) for x in (-9.0, -1.0, 7.0)]
    station.devices.camera.set_exposure(30.0)
    station.devices.head.show_lines(lines)
    image = station.devices.camera.grab()
    station.devices.head.off()
    return world, station.rig, lines, image


def _height_error(part, p: np.ndarray) -> np.ndarray:
    """(N,) mm: each point's height against the true surface within 0.3 mm of it (the
    table where the part is not), the nearest of those."""
    best = np.full(len(p), np.inf)
    for dx in (-0.3, 0.0, 0.3):
        for dy in (-0.3, 0.0, 0.3):
            z = part.height(p[:, 0] + dx, p[:, 1] + dy)
            z = np.where(np.isfinite(z), z, 0.0)
            best = np.minimum(best, np.abs(p[:, 2] - z))
    return best


def test_band_assignment_is_never_wrong_at_a_15_mm_step(step_frame):
    """Every point of a frame of three lines over steps up to 15 mm lies on the true surface
    (a centre taken for the wrong line would put it millimetres off); each line gives most
    of its points."""
    world, rig, lines, image = step_frame
    rec = ScanReconstructor(rig.camera, rig.head.pivot_height_mm, z_range_mm=(-25.0, 25.0),
                            min_points=10)
    rec.add_lines(image, lines, [0, 1, 2], (-0.5, 15.5), Packing())
    cloud = rec.cloud()
    part = world.parts[0]
    err = _height_error(part, cloud.points)
    assert err.max() < 1.5, f"{np.sum(err >= 1.5)} points off the surface: a wrong line"
    for k, (a, _) in enumerate(lines):
        mine = cloud.points[cloud.attributes["line"] == k]
        assert len(mine) > 100
        assert np.all(np.abs(mine[:, 0] - a[0]) < 1.5)


def test_a_packed_frame_measures_its_peaks_above_the_level_it_keeps(step_frame):
    """add_lines hands the room light's level kept (:class:`ExcessLight`) to the bands'
    detection: on no level the frame's lines are found; on a level the sensor cannot stand
    the floor above, none."""
    from insitu.reconstruct.scan import ExcessLight

    _, rig, lines, image = step_frame
    found = []
    for level in (0.0, float(np.iinfo(image.dtype).max)):
        rec = ScanReconstructor(rig.camera, rig.head.pivot_height_mm, min_points=10)
        excess = ExcessLight(np.zeros((2, *image.shape), image.dtype), level)
        found.append(rec.add_lines(image, lines, [0, 1, 2], (-0.5, 15.5), Packing(), excess))
    assert found[0] > 300 and found[1] == 0, found


def test_a_height_range_too_narrow_is_what_makes_lines_wrong(step_frame):
    """The same frame with bands for 10 … 15.5 mm only: the table and the low steps' stripes
    fall in the neighbours' bands — the heights bound the assignment (the survey frames
    measure them), so this must show points off the surface."""
    world, rig, lines, image = step_frame
    rec = ScanReconstructor(rig.camera, rig.head.pivot_height_mm, z_range_mm=(-25.0, 25.0),
                            min_points=10)
    rec.add_lines(image, lines, [0, 1, 2], (10.0, 15.5), Packing())
    pts = np.vstack([c[0] for c in rec._chunks])
    assert _height_error(world.parts[0], pts).max() > 3.0


CAMERA = {"width": 64, "height": 48, "K": [[60.0, 0, 32.0], [0, 60.0, 24.0], [0, 0, 1]],
          "dist": [0.0] * 5, "R": np.eye(3), "t": [0.0, 0.0, 300.0]}
HEAD = {"lens": "non-telecentric", "pivot_height_mm": 350.0, "field_size_mm": [200.0, 200.0],
        "z_range_mm": [-25.0, 25.0]}


def _line(x):
    return {"start": [x, -40.0], "end": [x, 40.0]}


def test_frames_of_several_lines_round_trip(tmp_path):
    img = np.zeros((48, 64), np.uint8)
    with SequenceWriter(tmp_path / "r", "scan", HEAD, camera=CAMERA) as w:
        w.add(img, lines=[_line(-8.0), _line(0.0), _line(8.0)], survey=True, exposure_ms=30.0)
        w.add(img, lines=[_line(-7.5), _line(0.5)], exposure_ms=20.0)
        w.add(img, lines=[_line(1.0)])
        w.add(img, line=_line(2.0))
    seq = Sequence.open(tmp_path / "r")
    assert [len(f.drawn()) for f in seq.frames] == [3, 2, 1, 1]
    assert seq.frames[1].drawn()[1] == ([0.5, -40.0], [0.5, 40.0])
    assert seq.frames[0].survey and not seq.frames[1].survey
    assert seq.frames[2].line.start == [1.0, -40.0]       # one entry reads as `line`
    data = json.loads((tmp_path / "r" / "sequence.json").read_text())
    assert data["frames"][1]["lines"][0] == _line(-7.5) and "line" not in data["frames"][1]


@pytest.mark.parametrize(("kind", "frame", "said"), [
    ("scan", {"line": _line(0.0), "lines": [_line(1.0)]}, "not both"),
    ("field-calibration", {"lines": [_line(0.0), _line(9.0)], "spot": [0.0, 0.0],
                           "plate_z_mm": 0.0}, "several lines in one frame"),
    ("scan", {"lines": []}, "lines"),
])
def test_bad_lines_are_refused_naming_the_field(tmp_path, kind, frame, said):
    img = np.zeros((48, 64), np.uint8)
    with pytest.raises(FormatError, match=said):
        with SequenceWriter(tmp_path / "r", kind, HEAD, camera=CAMERA) as w:
            w.add(img, **frame)
    assert not (tmp_path / "r").exists()


def test_a_frames_lines_are_drawn_from_the_end_nearest_the_head():
    """The same lines back and forth, starting where the head is: after a frame that ended
    at the far end of its last line, the next starts at the near end of its nearest line."""
    from insitu.services.scan_frames import drawing_order

    lines = [(np.array([float(x), -40.0]), np.array([float(x), 40.0])) for x in (0, 8, 16)]
    as_planned = drawing_order(lines)
    assert [tuple(a) for a, _ in as_planned] == [(0, -40), (8, 40), (16, -40)]
    drawn = drawing_order(lines, (16.5, 40.0))        # the head at the last line's far end
    assert tuple(drawn[0][0]) == (16.0, 40.0) and tuple(drawn[-1][1]) == (0.0, -40.0)
    undirected = lambda ls: sorted(tuple(sorted((tuple(a), tuple(b)))) for a, b in ls)  # noqa: E731
    assert undirected(drawn) == undirected(lines)                   # the same lines
    assert all(np.sign(b[1] - a[1]) != np.sign(d[1] - c[1])       # back and forth
               for (a, b), (c, d) in zip(drawn, drawn[1:]))


def _room(rng, k: int) -> np.ndarray:
    """(H, W) float DN: ``k`` exposures of a textured room light (8 DN an exposure, its
    texture ±2 DN in 3-px cells, the same in every exposure) and a dark offset of 3 DN."""
    cells = np.kron(rng.uniform(-2.0, 2.0, (H // 3 + 1, W // 3 + 1)), np.ones((3, 3)))
    return 3.0 + k * (8.0 + cells[:H, :W])


def test_the_other_exposures_room_light_goes_its_level_stays():
    """(K − 1)/K of a laser-off frame of a 4-line exposure taken from the frame leaves one
    exposure's texture, and the level of four, on which a faint stripe (26 DN over the room
    light) still clears the detector's floor (40 DN) in every column; the frame less the
    laser-off frame's level too loses it."""
    from insitu.reconstruct.scan import excess_room_light, less_room_light
    from insitu.vision.extract import extract_centres

    rng = np.random.default_rng(3)
    room, k = _room(np.random.default_rng(1), 4), 4
    v = np.arange(H, dtype=np.float64)[:, None]
    stripe = 26.0 * np.exp(-0.5 * ((v - 50.0) / 1.5) ** 2) * np.ones((1, W))
    frame = np.clip(np.rint(room + stripe + rng.normal(0, 1.0, (H, W))), 0, 255).astype(np.uint8)
    off = np.clip(np.rint(room + rng.normal(0, 1.0, (H, W))), 0, 255).astype(np.uint8)
    left = less_room_light(frame, excess_room_light(off, k))
    one = _room(np.random.default_rng(1), 1)
    background = left[:40].astype(float) - left[:40].mean()
    assert np.std(background - (one[:40] - one[:40].mean())) < 1.8      # one exposure's texture
    assert abs(left[:40].mean() - room[:40].mean()) < 2.0                # four exposures' level
    found = extract_centres(left, band=(np.full(W, 40.0), np.full(W, 60.0)))
    assert len(found) >= W - 4 and np.all(np.abs(found.v - 50.0) < 0.5)
