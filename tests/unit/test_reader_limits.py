"""Readers refuse what is not a file of their kind before reading it (issue 16): PLY checked
against its header, special files and oversized files refused, image headers read before the
pixels, recording frames kept inside the recording, DXF/SVG coordinates that are not finite
refused before flattening, and flattening within a segment budget. Each in one line, fast."""

import json
import os
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats import limits
from insitu.formats.images import image_size, read_image
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.formats.sequence import Sequence
from insitu.formats.sequence_writer import SequenceWriter
from insitu.formats.validation import read_json
from insitu.marking import read_job
from insitu.patterns import vector
from insitu.patterns.dxf import load_dxf
from insitu.patterns.svg import load_svg

SRC = Path(__file__).resolve().parents[2] / "src"
CAMERA = {"width": 32, "height": 24, "K": [[40.0, 0, 16.0], [0, 40.0, 12.0], [0, 0, 1]],
          "dist": [0, 0, 0, 0, 0], "R": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "t": [0, 0, 300.0]}
HEAD = {"lens": "non-telecentric", "pivot_height_mm": 350.0, "field_size_mm": [200, 200],
        "z_range_mm": [-25.0, 25.0]}


def _refused(read, path, match):
    t = time.perf_counter()
    with pytest.raises(FormatError) as e:
        read(path)
    assert time.perf_counter() - t < 1.0
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg, msg
    assert match in msg, msg
    return msg


# ---------------------------------------------------------------------------------- PLY
@pytest.fixture(scope="module")
def plys(tmp_path_factory):
    import open3d as o3d
    d = tmp_path_factory.mktemp("ply")
    pts = np.random.default_rng(1).uniform(-5, 5, (20, 3))
    write_ply(d / "binary.ply", PointCloud(pts, {"intensity": np.linspace(0, 1, 20)}))
    o3d.t.io.write_point_cloud(str(d / "ascii.ply"), o3d.t.geometry.PointCloud(
        o3d.core.Tensor(pts)), write_ascii=True)
    return d, pts


@pytest.mark.parametrize("fmt", ["binary", "ascii"])
def test_valid_ply_reads_exactly(plys, fmt):
    d, pts = plys
    cloud = read_ply(d / f"{fmt}.ply")
    assert np.allclose(cloud.points, pts, atol=1e-5 if fmt == "ascii" else 0)


@pytest.mark.parametrize("fmt", ["binary", "ascii"])
@pytest.mark.parametrize("case, match", [
    ("header-only", "truncated"), ("truncated", "truncated"), ("count+1", "truncated"),
    ("count-1", "after the data the header describes"), ("4e9", "whole number"),
    ("4000000000", "truncated"), ("-5", "whole number"), ("no-xyz", "no vertex element with x, y, z"),
    ("no-end", "incomplete PLY header"), ("nan", "not finite")])
def test_broken_ply_is_one_line_and_silent(plys, tmp_path, capfd, fmt, case, match):
    raw = (plys[0] / f"{fmt}.ply").read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    first = raw[end:].split()[0] if fmt == "ascii" else raw[end:end + 8]
    bad = {"header-only": raw[:end], "truncated": raw[:-20],
           "count+1": raw.replace(b"vertex 20", b"vertex 21"),
           "count-1": raw.replace(b"vertex 20", b"vertex 19"),
           "4e9": raw.replace(b"vertex 20", b"vertex 4e9"),
           "4000000000": raw.replace(b"vertex 20", b"vertex 4000000000"),
           "-5": raw.replace(b"vertex 20", b"vertex -5"),
           "no-xyz": raw.replace(b"property double x", b"property double w"),
           "no-end": raw[:end - 4],
           "nan": raw[:end] + raw[end:].replace(first, b"nan" if fmt == "ascii"
                                                 else struct.pack("<d", float("nan")), 1),
           }[case]
    path = tmp_path / "bad.ply"
    path.write_bytes(bad)
    _refused(read_ply, path, match)
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out, err)          # Open3D says nothing: it reads nothing


def test_mark_with_a_broken_cloud_exits_1_and_writes_nothing(plys, tmp_path):
    raw = (plys[0] / "binary.ply").read_bytes()
    (tmp_path / "bad.ply").write_bytes(raw.replace(b"vertex 20", b"vertex 21"))
    (tmp_path / "r.svg").write_text("<svg xmlns='http://www.w3.org/2000/svg' width='5mm' "
                                    "height='5mm' viewBox='0 0 5 5'><rect width='5' height='5'/></svg>")
    out = tmp_path / "job.json"
    res = subprocess.run([sys.executable, "-c", "from insitu.cli.main import main; main()",
                          "mark", "--cloud",
                          str(tmp_path / "bad.ply"), "--pattern", str(tmp_path / "r.svg"),
                          "--at", "0", "0", "--width", "5", "-o", str(out)],
                         capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(SRC)})
    assert res.returncode == 1, res
    lines = [ln for ln in (res.stdout + res.stderr).splitlines() if ln.strip()]
    assert len(lines) == 1 and "bad.ply" in lines[0] and "truncated" in lines[0], lines
    assert not out.exists() and not list(tmp_path.glob("*.tmp*"))


# --------------------------------------------------------------------- special files, sizes
def test_json_from_a_device_or_a_fifo_is_refused_unread(tmp_path):
    _refused(read_json, Path("/dev/zero"), "a character device")
    fifo = tmp_path / "job.json"
    os.mkfifo(fifo)
    _refused(read_job, fifo, "a FIFO")                   # open() would block for a writer
    link = tmp_path / "rig.json"
    link.symlink_to("/dev/zero")
    _refused(read_json, link, "a character device")
    _refused(read_json, tmp_path, "a folder")


def test_files_over_the_limit_are_refused_unread(tmp_path, monkeypatch):
    path = tmp_path / "big.json"
    path.write_text(json.dumps({"x": "a" * 200}))
    monkeypatch.setattr("insitu.formats.validation.MAX_JSON_BYTES", 100)
    _refused(read_json, path, "larger than the 100 bytes limit")
    assert limits.read_limited(path, 1000) == path.read_bytes()
    with pytest.raises(FormatError, match="larger than"):
        limits.read_limited(path, 100)


# ------------------------------------------------------------------------------- images
def _png_header(w: int, h: int) -> bytes:
    ihdr = b"IHDR" + struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    idat = b"IDAT" + zlib.compress(b"\0" * 64)
    return (b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + ihdr
            + struct.pack(">I", zlib.crc32(ihdr)) + struct.pack(">I", len(idat) - 4) + idat
            + struct.pack(">I", zlib.crc32(idat)) + b"\0\0\0\0IEND\xaeB`\x82")


def test_a_huge_png_is_refused_from_its_header(tmp_path):
    path = tmp_path / "huge.png"
    path.write_bytes(_png_header(20000, 20000))       # 400 Mpx claimed in 100 bytes
    assert image_size(path, max_pixels=10**9) == (20000, 20000)      # the header, no pixels
    msg = _refused(read_image, path, "20000x20000 pixels")
    assert "before decoding" in msg
    from insitu.patterns.raster import load_image
    _refused(load_image, path, "before decoding")


def test_a_frame_of_the_wrong_size_is_refused_before_decoding(tmp_path):
    rec = tmp_path / "rec"
    with SequenceWriter(rec, "scan", HEAD, CAMERA) as w:
        w.add(np.zeros((24, 32), np.uint8), line={"start": [0, -5], "end": [0, 5]})
    (rec / "frames" / "00000.png").write_bytes(_png_header(20000, 20000))
    with pytest.raises(FormatError, match="image is 20000x20000 pixels, camera is 32x24"):
        Sequence.open(rec).read_frame(0)


def test_frames_that_lead_out_of_the_recording_are_refused(tmp_path):
    rec = tmp_path / "rec"
    with SequenceWriter(rec, "scan", HEAD, CAMERA) as w:
        for x in (0.0, 1.0):
            w.add(np.full((24, 32), 7, np.uint8), line={"start": [x, -5], "end": [x, 5]})
    frame = rec / "frames" / "00001.png"
    outside = tmp_path / "elsewhere.png"
    frame.rename(outside)
    frame.symlink_to(outside)
    with pytest.raises(FormatError, match=r"00001\.png: the frame file leads out of"):
        Sequence.open(rec)
    frame.unlink()
    frame.symlink_to("00000.png")                          # a link inside the folder is fine
    assert Sequence.open(rec).read_frame(1).shape == (24, 32)
    frame.unlink()
    os.mkfifo(frame)
    with pytest.raises(FormatError, match="a FIFO"):
        Sequence.open(rec)


# ------------------------------------------------------------------------------ DXF, SVG
def _in_subprocess(code: str) -> str:
    """Run ``code`` in a fresh interpreter with a time limit (a regression would hang)."""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, env={**os.environ, "PYTHONPATH": str(SRC)})
    assert res.returncode == 0, res.stderr[-2000:]
    return res.stdout.strip()


@pytest.mark.parametrize("entity", [
    "add_arc((0, 0, float('nan')), 5, 0, 90)", "add_circle((0, 0, float('inf')), 5)",
    "add_arc((0, 0), 5, float('nan'), 90)", "add_circle((0, 0), 5, dxfattribs={'extrusion': "
    "(0, float('nan'), 1)})", "add_lwpolyline([(0, 0), (float('nan'), 0), (10, 5)])",
    "add_spline([(0, 0), (3, float('inf')), (6, -1), (9, 3)])"])
def test_dxf_entity_with_a_non_finite_number_is_refused_quickly(tmp_path, entity):
    path = tmp_path / "nan.dxf"
    out = _in_subprocess(
        "import ezdxf, time\nfrom insitu.errors import FormatError\n"
        "from insitu.patterns.dxf import load_dxf\n"
        f"doc = ezdxf.new(); doc.modelspace().{entity}; doc.saveas({str(path)!r})\n"
        "t = time.perf_counter()\ntry:\n    load_dxf(" + repr(str(path)) + ")\n"
        "    print('accepted')\nexcept FormatError as e:\n"
        "    print(f'{time.perf_counter() - t:.3f}', e)\n")
    seconds, msg = out.split(" ", 1)
    assert float(seconds) < 1.0 and "nan.dxf" in msg and "not a finite number" in msg, out


@pytest.mark.parametrize("body", [
    "<path d='M 0 0 C 1e400 0 3 3 5 5 Z'/>", "<g transform='scale(1e308)'><path "
    "d='M 0 0 C 10 0 3 3 5 5 Z'/></g>", "<circle cx='0' cy='0' r='1e400'/>"])
def test_svg_with_a_non_finite_coordinate_is_refused(tmp_path, body):
    path = tmp_path / "nan.svg"
    path.write_text("<svg xmlns='http://www.w3.org/2000/svg' width='100mm' height='100mm' "
                    f"viewBox='0 0 100 100'>{body}</svg>")
    _refused(load_svg, path, "not a finite number")


def test_flattening_has_a_segment_budget(tmp_path, monkeypatch):
    import ezdxf
    monkeypatch.setattr(vector.Budget.__init__, "__defaults__", (500,))
    doc = ezdxf.new()
    for i in range(40):
        doc.modelspace().add_circle((10 * i, 0), 4)
    doc.saveas(tmp_path / "many.dxf")
    msg = _refused(load_dxf, tmp_path / "many.dxf", "flattens to more than 500 segments")
    assert "CIRCLE #" in msg                             # the entity that crossed the budget
    (tmp_path / "many.svg").write_text(
        "<svg xmlns='http://www.w3.org/2000/svg' width='100mm' height='100mm' viewBox='0 0 100 "
        "100'>" + "".join(f"<circle cx='{i}' cy='5' r='3'/>" for i in range(60)) + "</svg>")
    _refused(load_svg, tmp_path / "many.svg", ": the drawing flattens to more than 500")
    monkeypatch.setattr(vector.Budget.__init__, "__defaults__", (vector.MAX_SEGMENTS,))
    assert len(load_dxf(tmp_path / "many.dxf").paths) == 40


def test_drawings_over_the_size_limit_are_refused(tmp_path, monkeypatch):
    path = tmp_path / "big.svg"
    path.write_text("<svg xmlns='http://www.w3.org/2000/svg'>" + " " * 300 + "</svg>")
    monkeypatch.setattr(vector, "MAX_DRAWING_BYTES", 100)
    _refused(load_svg, path, "larger than the 100 bytes limit for a drawing")
    _refused(load_svg, Path("/dev/zero"), "a character device")


def test_photos_that_lead_out_of_their_folder_are_refused(tmp_path):
    import cv2

    from insitu.calibrate.photos import image_files
    from insitu.errors import CalibrationError
    (tmp_path / "photos").mkdir()
    cv2.imwrite(str(tmp_path / "photos" / "a.png"), np.zeros((8, 8), np.uint8))
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((8, 8), np.uint8))
    assert image_files(tmp_path / "photos") == [tmp_path / "photos" / "a.png"]
    (tmp_path / "photos" / "b.png").symlink_to(tmp_path / "b.png")
    with pytest.raises(CalibrationError, match=r"b\.png: the photo leads out of"):
        image_files(tmp_path / "photos")


@pytest.mark.parametrize("args", [["job", "show", "{fifo}"], ["job", "show", "/dev/zero"],
                                  ["mark", "--cloud", "/dev/zero", "--pattern", 'text:"A"',
                                   "--at", "0", "0", "-o", "{out}"]])
def test_commands_refuse_special_files_in_one_line(tmp_path, args):
    fifo, out = tmp_path / "job.json", tmp_path / "out.json"
    os.mkfifo(fifo)
    t = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", "from insitu.cli.main import main; main()",
                          *[a.format(fifo=fifo, out=out) for a in args]],
                         capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": str(SRC)})
    lines = [ln for ln in (res.stdout + res.stderr).splitlines() if ln.strip()]
    assert res.returncode == 1 and len(lines) == 1, (res.returncode, lines)
    assert ("a FIFO" if "{fifo}" in args else "a character device") in lines[0]
    assert not out.exists() and time.perf_counter() - t < 60
