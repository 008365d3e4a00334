"""Recorded sequences (docs/formats.md, recorded sequence): round trip, and one-line errors
naming the problem for every kind of bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats.sequence import CameraSpec, Sequence, SequenceSpec
from insitu.formats.sequence_writer import SequenceWriter
from tiny_sequence import CAMERA, HEAD, H, W, line

BOARD = {"cols": 9, "rows": 6, "square_mm": 10.0}


def _images(n=3, dtype=np.uint8, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, np.iinfo(dtype).max, (H, W), dtype=dtype) for _ in range(n)]


@pytest.fixture
def rec(tmp_path) -> Path:
    """A valid 3-frame 64x48 scan sequence."""
    out = tmp_path / "rec"
    with SequenceWriter(out, "scan", HEAD, camera=CAMERA, truth={"seed": 3}) as w:
        for i, img in enumerate(_images()):
            w.add(img, line=line(float(i)), exposure_ms=2.0)
    return out


def _edit(rec: Path, change) -> None:
    data = json.loads((rec / "sequence.json").read_text())
    change(data)
    (rec / "sequence.json").write_text(json.dumps(data))


def _fails(rec: Path, *words: str) -> str:
    with pytest.raises(FormatError) as info:
        seq = Sequence.open(rec)
        for _ in seq:
            pass
    msg = str(info.value)
    assert "\n" not in msg
    for word in words:
        assert word in msg, msg
    return msg


# -- round trip ---------------------------------------------------------------------------

@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_round_trip_is_identical(tmp_path, dtype):
    images = _images(dtype=dtype)
    truth = {"K": np.eye(3), "z": np.float32(1.5), "n": np.int64(4), "parts": [(1, 2)]}
    with SequenceWriter(tmp_path / "rec", "scan", HEAD, camera=CAMERA, truth=truth) as w:
        for i, img in enumerate(images):
            assert w.add(img, line=line(i - 1.0), plate_z_mm=0.5, tool="x") == i
    seq = Sequence.open(tmp_path / "rec")
    assert (seq.kind, len(seq), seq.checkerboard) == ("scan", 3, None)
    assert [f.file for f in seq.frames] == ["frames/00000.png", "frames/00001.png",
                                            "frames/00002.png"]
    assert seq.frames[2].line.start == [1.0, -40.0] and seq.frames[0].plate_z_mm == 0.5
    assert seq.frames[0].model_extra == {"tool": "x"}         # unknown fields are kept
    assert seq.scan_head.pivot_height_mm == 350.0
    np.testing.assert_array_equal(seq.camera.K_array, np.array(CAMERA["K"]))
    assert seq.camera.R_array.shape == (3, 3) and seq.camera.t_array.dtype == np.float64
    assert seq.camera.dist_array.shape == (5,)
    for (i, frame, image), expected in zip(seq, images, strict=True):
        assert frame is seq.frames[i]
        assert image.dtype == dtype and image.shape == (H, W)
        np.testing.assert_array_equal(image, expected)
    assert seq.has_truth
    assert seq.read_truth() == {"K": np.eye(3).tolist(), "z": 1.5, "n": 4, "parts": [[1, 2]]}
    assert not list(tmp_path.glob(".*"))                       # no temp folder left


def test_field_and_camera_calibration_round_trip(tmp_path):
    with SequenceWriter(tmp_path / "f", "field-calibration", HEAD, camera=CAMERA) as w:
        w.add(_images(1)[0], spot=np.array([-90.0, 90.0]), plate_z_mm=np.float64(0.0))
    seq = Sequence.open(tmp_path / "f")
    assert seq.frames[0].spot == [-90.0, 90.0] and not seq.has_truth
    with SequenceWriter(tmp_path / "c", "camera-calibration", HEAD, checkerboard=BOARD) as w:
        w.add(_images(1)[0])
    seq = Sequence.open(tmp_path / "c")
    assert seq.camera is None and seq.checkerboard.cols == 9


def test_writer_replaces_an_existing_sequence(rec):
    with SequenceWriter(rec, "scan", HEAD, camera=CAMERA) as w:
        w.add(_images(1, seed=5)[0], line=line(7.0))
    seq = Sequence.open(rec)
    assert len(seq) == 1 and not seq.has_truth
    assert not (rec / "frames" / "00002.png").exists()
    assert not list(rec.parent.glob(".*"))


def test_sequence_spec_validates_a_dict():
    spec = {"format": "insitu-sequence/1", "kind": "height-calibration", "camera": CAMERA,
            "scan_head": HEAD, "frames": [{"file": "frames/00000.png", "line": line(-12.0),
                                           "plate_z_mm": 0.0}]}
    assert SequenceSpec.model_validate(spec).frames[0].line.end == [-12.0, 40.0]


# -- writer failures leave nothing --------------------------------------------------------

def test_exception_in_writer_leaves_no_folder(tmp_path):
    with pytest.raises(RuntimeError):
        with SequenceWriter(tmp_path / "rec", "scan", HEAD, camera=CAMERA) as w:
            w.add(_images(1)[0], line=line(0.0))
            raise RuntimeError("camera unplugged")
    assert list(tmp_path.iterdir()) == []


def test_exception_in_writer_keeps_the_old_sequence(rec):
    before = (rec / "sequence.json").read_text()
    with pytest.raises(KeyboardInterrupt):
        with SequenceWriter(rec, "scan", HEAD, camera=CAMERA):
            raise KeyboardInterrupt
    assert (rec / "sequence.json").read_text() == before
    assert [p.name for p in rec.parent.iterdir()] == ["rec"]


@pytest.mark.parametrize("image, fields, words", [
    (np.zeros((H, W), np.float32), {"line": line(0.0)}, ["frames[0]", "uint8", "float32"]),
    (np.zeros((H, W, 3), np.uint8), {"line": line(0.0)}, ["frames[0]", "(H, W)"]),
    (np.zeros((H, W + 1), np.uint8), {"line": line(0.0)}, ["65x48", "64x48"]),
    (np.zeros((H, W), np.uint8), {}, ["frames[0].line", "missing", "'scan'"]),
    (np.zeros((H, W), np.uint8), {"line": {"start": [1.0], "end": [0, 1]}},
     ["frames[0].line.start", "expected 2 numbers", "[1.0]"]),
    (np.zeros((H, W), np.uint8), {"line": line(0.0), "exposure_ms": -1},
     ["frames[0].exposure_ms", "-1 is outside 0.001 … 10000 ms"]),
])
def test_writer_refuses_bad_frames_and_leaves_nothing(tmp_path, image, fields, words):
    with pytest.raises(FormatError) as info:
        with SequenceWriter(tmp_path / "rec", "scan", HEAD, camera=CAMERA) as w:
            w.add(image, **fields)
    for word in words:
        assert word in str(info.value), str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_writer_refuses_bad_setup(tmp_path):
    with pytest.raises(FormatError, match="kind: expected"):
        SequenceWriter(tmp_path / "rec", "scna", HEAD, camera=CAMERA)
    with pytest.raises(FormatError, match="camera: missing"):
        SequenceWriter(tmp_path / "rec", "scan", HEAD)
    with pytest.raises(FormatError, match=r"scan_head\.pivot_height_mm: -1 is outside 1 … 2000 mm"):
        SequenceWriter(tmp_path / "rec", "scan", {**HEAD, "pivot_height_mm": -1}, camera=CAMERA)
    with pytest.raises(FormatError, match=r"camera\.R: expected a rotation"):
        SequenceWriter(tmp_path / "rec", "scan", HEAD, camera={**CAMERA, "R": 2 * np.eye(3)})
    with pytest.raises(FormatError, match="folder .*nowhere does not exist"):
        with SequenceWriter(tmp_path / "nowhere" / "rec", "scan", HEAD, camera=CAMERA):
            pass


def test_writer_with_no_frames_or_no_checkerboard_leaves_nothing(tmp_path):
    with pytest.raises(FormatError, match="frames: expected at least one frame"):
        with SequenceWriter(tmp_path / "rec", "scan", HEAD, camera=CAMERA):
            pass
    with pytest.raises(FormatError, match="checkerboard: missing"):
        with SequenceWriter(tmp_path / "rec", "camera-calibration", HEAD) as w:
            w.add(_images(1)[0])
    with pytest.raises(FormatError, match="truth.json: cannot be written"):
        with SequenceWriter(tmp_path / "rec", "scan", HEAD, camera=CAMERA,
                            truth={"x": math.nan}) as w:
            w.add(_images(1)[0], line=line(0.0))
    assert list(tmp_path.iterdir()) == []


# -- every kind of bad input is a one-line FormatError naming the problem ------------------

def test_missing_folder(tmp_path):
    _fails(tmp_path / "nope", "nope", "no such sequence folder")


def test_folder_is_a_file(tmp_path):
    (tmp_path / "f").write_text("")
    _fails(tmp_path / "f", "not a folder")


def test_missing_sequence_json(rec):
    (rec / "sequence.json").unlink()
    _fails(rec, "sequence.json", "missing")


def test_bad_json(rec):
    (rec / "sequence.json").write_text('{\n "format": "insitu-sequence/1"\n "kind": 1}')
    msg = _fails(rec, "sequence.json: not valid JSON (line 3, column 2: Expecting ',' delimiter)")
    assert msg.startswith(str(rec))


def test_not_utf8(rec):
    (rec / "sequence.json").write_bytes(b"\xff\xfe{}")
    _fails(rec, "not valid JSON", "UTF-8")


def test_not_an_object(rec):
    (rec / "sequence.json").write_text("[1, 2]")
    _fails(rec, "sequence.json: expected a JSON object, got [1, 2]")


@pytest.mark.parametrize("change, words", [
    (lambda d: d.update(format="insitu-sequence/2"),
     ["format: expected 'insitu-sequence/1', got 'insitu-sequence/2'"]),
    (lambda d: d.pop("format"), ["format: missing"]),
    (lambda d: d.update(kind="scna"), ["kind: expected 'scan', ", "got 'scna'"]),
    (lambda d: d.pop("camera"), ["camera: missing (required in a 'scan' sequence)"]),
    (lambda d: d.pop("scan_head"), ["scan_head: missing"]),
    (lambda d: d["scan_head"].update(lens="fisheye"), ["scan_head.lens", "'fisheye'"]),
    (lambda d: d["scan_head"].update(z_range_mm=[5, -5]), ["scan_head.z_range_mm", "low < high"]),
    (lambda d: d["scan_head"].update(field_size_mm=[200, 0]), ["scan_head.field_size_mm"]),
    (lambda d: d.update(frames=[]), ["frames: expected at least one frame"]),
    (lambda d: d["frames"][1].pop("line"),
     ["frames[1].line: missing (required in a 'scan' sequence)"]),
    (lambda d: [f.pop("line") for f in d["frames"]], ["frames[0].line: missing", "(and 2 more)"]),
    (lambda d: d["frames"][2]["line"].update(start=[1.0]),
     ["frames[2].line.start: expected 2 numbers, got [1.0]"]),
    (lambda d: d["frames"][2]["line"].update(end=d["frames"][2]["line"]["start"]),
     ["frames[2].line: expected start != end"]),
    (lambda d: d["frames"][0].update(file="../elsewhere.png"), ["frames[0].file", "relative"]),
    (lambda d: d["frames"][0].update(file="/etc/passwd"), ["frames[0].file", "relative"]),
    (lambda d: d["frames"][0].update(exposure_ms="long"), ["frames[0].exposure_ms", "'long'"]),
    (lambda d: d["camera"]["K"][0].__setitem__(0, math.nan),
     ["camera.K[0][0]: expected a finite number, got NaN"]),
    (lambda d: d["camera"]["t"].__setitem__(2, math.inf), ["camera.t[2]", "finite"]),
    (lambda d: d["camera"]["K"][1].__setitem__(1, -60.0), ["camera.K", "fy"]),
    (lambda d: d["camera"]["K"].__setitem__(2, [0, 0.1, 1]), ["camera.K[2]: expected [0, 0, 1]"]),
    (lambda d: d["camera"].update(K=[[1, 0], [0, 1]]), ["camera.K: expected a 3x3 matrix"]),
    (lambda d: d["camera"].update(R=[[1, 0, 0], [0, 1, 0], [0, 0, -1]]),
     ["camera.R: expected a rotation", "det = -1"]),
    (lambda d: d["camera"].update(R=[[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]),
     ["camera.R: expected a rotation", "0.1"]),
    (lambda d: d["camera"].update(dist=[0, 0, 0]), ["camera.dist: expected 4, 5, 8, 12 or 14"]),
    (lambda d: d["camera"].update(width=0), ["camera.width: 0 is outside 1 … 100000 px"]),
    (lambda d: d["camera"].update(height="tall"), ["camera.height: expected an integer"]),
    (lambda d: d.update(kind="field-calibration"),
     ["frames[0].spot: missing (required in a 'field-calibration' sequence)", "(and 5 more)"]),
    (lambda d: d.update(kind="height-calibration"), ["frames[0].plate_z_mm: missing"]),
    (lambda d: d.update(kind="camera-calibration"), ["checkerboard: missing"]),
])
def test_bad_sequence_json(rec, change, words):
    _edit(rec, change)
    msg = _fails(rec, *words)
    assert msg.startswith(f"{rec / 'sequence.json'}: ")


def test_field_calibration_frame_without_spot_or_plate_z(rec):
    def field(d, drop):
        d["kind"] = "field-calibration"
        for f in d["frames"]:
            f.update(spot=[0.0, 0.0], plate_z_mm=0.0)
        d["frames"][1].pop(drop)
    _edit(rec, lambda d: field(d, "spot"))
    _fails(rec, "frames[1].spot: missing (required in a 'field-calibration' sequence)")
    _edit(rec, lambda d: d["frames"][1].update(spot=[0, 0]))
    Sequence.open(rec)
    _edit(rec, lambda d: d["frames"][2].pop("plate_z_mm"))
    _fails(rec, "frames[2].plate_z_mm: missing (required in a 'field-calibration' sequence)")


def test_missing_frame_file(rec):
    (rec / "frames" / "00001.png").unlink()
    (rec / "frames" / "00002.png").unlink()
    _fails(rec, "frame file frames/00001.png is missing", "2 of 3")


def test_corrupt_png(rec):
    (rec / "frames" / "00001.png").write_bytes(b"\x89PNG garbage" * 10)
    seq = Sequence.open(rec)
    seq.read_frame(0)
    with pytest.raises(FormatError, match=r"00001\.png: not a readable image"):
        seq.read_frame(1)
    (rec / "frames" / "00002.png").write_bytes(b"")
    with pytest.raises(FormatError, match=r"00002\.png: not a readable image"):
        seq.read_frame(2)


def test_wrong_image_size(rec):
    cv2.imwrite(str(rec / "frames" / "00002.png"), np.zeros((H, W - 4), np.uint8))
    _fails(rec, "00002.png: image is 60x48 pixels, camera is 64x48")


def test_rgb_image(rec):
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[..., 2] = 200
    cv2.imwrite(str(rec / "frames" / "00000.png"), rgb)
    _fails(rec, "00000.png", "single-channel", "3 channels")


def test_grey_rgb_and_bgra_images(rec):
    grey = _images(1, seed=9)[0]
    cv2.imwrite(str(rec / "frames" / "00000.png"), np.dstack([grey] * 3))
    cv2.imwrite(str(rec / "frames" / "00001.png"), np.dstack([grey] * 4))
    seq = Sequence.open(rec)
    np.testing.assert_array_equal(seq.read_frame(0), grey)
    with pytest.raises(FormatError, match="4 channels"):
        seq.read_frame(1)


def test_truth_errors(rec):
    (rec / "truth.json").write_text("[]")
    with pytest.raises(FormatError, match="truth.json: expected a JSON object"):
        Sequence.open(rec).read_truth()
    (rec / "truth.json").unlink()
    assert not Sequence.open(rec).has_truth
    with pytest.raises(FormatError, match="truth.json"):
        Sequence.open(rec).read_truth()


def test_camera_spec_arrays():
    cam = CameraSpec.model_validate({**CAMERA, "dist": [0.0] * 8})
    assert cam.K_array.shape == (3, 3) and cam.dist_array.shape == (8,)
    assert cam.K_array.dtype == np.float64
