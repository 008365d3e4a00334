"""The ambient frame: one laser-off frame under the room light before a scan's lines, recorded
as ambient.png, giving every point its grey value (cloud attribute and PLY property
``ambient``), and the cloud picture that shows it."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.formats.sequence import Sequence
from insitu.formats.sequence_writer import SequenceWriter
from insitu.reconstruct.preview import save_cloud_picture
from insitu.reconstruct.scan import ScanReconstructor, grey_at
from insitu.services.record import record_scan
from insitu.services.room_light import ACCEPT, grab_room_light, station_room_light
from insitu.services.scan import scan_live, scan_replay
from insitu.services.station import simulated
from insitu.sim.rig import default_rig
from insitu.sim.world import sim_world

HEAD = default_rig().operator.head.spec()
CAM = {"width": 64, "height": 48, "K": [[100.0, 0, 32], [0, 100.0, 24], [0, 0, 1]],
       "dist": [0.0] * 5, "R": [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], "t": [0.0, 0, 300]}
LINE = {"start": [0.0, -5.0], "end": [0.0, 5.0]}


def _write(folder, ambient=None, exposure_ms=None):
    with SequenceWriter(folder, "scan", HEAD, camera=CAM) as w:
        if ambient is not None:
            w.add_ambient(ambient, exposure_ms=exposure_ms)
        w.add(np.zeros((48, 64), np.uint8), line=LINE)
    return folder


# -- the recording ----------------------------------------------------------------------------
def test_sequence_keeps_the_ambient_frame_and_reads_recordings_without_one(tmp_path):
    img = np.random.default_rng(0).integers(0, 65535, (48, 64), dtype=np.uint16)
    seq = Sequence.open(_write(tmp_path / "a", img, 80.0))
    assert seq.ambient.file == "ambient.png" and seq.ambient.exposure_ms == 80.0
    assert np.array_equal(seq.read_ambient(), img) and len(seq) == 1
    data = json.loads((tmp_path / "a" / "sequence.json").read_text())
    assert data["ambient"] == {"file": "ambient.png", "exposure_ms": 80.0}
    plain = Sequence.open(_write(tmp_path / "b"))
    assert plain.ambient is None and plain.read_ambient() is None
    assert "ambient" not in json.loads((tmp_path / "b" / "sequence.json").read_text())


def test_a_missing_or_wrong_ambient_frame_is_one_line(tmp_path):
    folder = _write(tmp_path / "a", np.zeros((48, 64), np.uint8))
    (folder / "ambient.png").unlink()
    with pytest.raises(FormatError, match=r"ambient.png: missing \(sequence.json names it"):
        Sequence.open(folder)
    with pytest.raises(FormatError, match=r"ambient: image is 10x48 pixels, camera is 64x48"):
        _write(tmp_path / "b", np.zeros((48, 10), np.uint8))
    folder = _write(tmp_path / "c", np.zeros((48, 64), np.uint8))
    data = json.loads((folder / "sequence.json").read_text())
    data["ambient"]["file"] = "../x.png"
    (folder / "sequence.json").write_text(json.dumps(data))
    with pytest.raises(FormatError, match=r"ambient.file: expected a path relative"):
        Sequence.open(folder)


# -- the grey value of each point ---------------------------------------------------------------
@pytest.mark.parametrize("dtype, full", [(np.uint8, 255.0), (np.uint16, 65535.0)])
def test_grey_at_is_bilinear_in_fractions_of_full_scale(dtype, full):
    v, u = np.mgrid[0:20, 0:30]
    img = (2 * u + 3 * v).astype(dtype)                    # linear: bilinear is exact
    uv = np.array([[0.0, 0.0], [10.25, 4.5], [28.75, 18.1]])
    expect = (2 * uv[:, 0] + 3 * uv[:, 1]) / full
    got = grey_at(img, uv)
    assert got.dtype == np.float32 and np.allclose(got, expect, atol=1e-6)


def test_grey_at_takes_full_scale_from_the_cameras_bits():
    img = np.full((8, 8), 2048, np.uint16)                 # a Mono12 frame's mid grey
    uv = np.array([[3.0, 4.0]])
    assert grey_at(img, uv, 12)[0] == pytest.approx(2048 / 4095, abs=1e-6)
    assert grey_at(img, uv)[0] == pytest.approx(2048 / 65535, abs=1e-6)


def test_ply_keeps_ambient_and_refuses_it_out_of_range(tmp_path):
    pts = np.random.default_rng(1).normal(size=(50, 3))
    amb = np.linspace(0, 1, 50).astype(np.float32)
    write_ply(tmp_path / "c.ply", PointCloud(pts, {"line": np.arange(50), "ambient": amb}))
    back = read_ply(tmp_path / "c.ply")
    assert back.attributes["ambient"].dtype == np.float32
    assert np.array_equal(back.attributes["ambient"], amb)
    write_ply(tmp_path / "d.ply", PointCloud(pts, {"ambient": amb * 2}))
    with pytest.raises(FormatError, match=r"d.ply: vertex 25: ambient 1.02041 is outside 0 … 1 of full scale \(25 of 50"):
        read_ply(tmp_path / "d.ply")


# -- the auto-exposure --------------------------------------------------------------------------
class LinearCamera:
    """A linear 8-bit sensor looking at ``scene`` (DN per ms); records what it was told."""

    def __init__(self, scene, exposure_ms=10.0):
        self.scene, self.exposure_ms, self.width, self.height = scene, exposure_ms, 8, 8
        self.set, self.grabs = [], 0

    def set_exposure(self, exposure_ms):
        self.exposure_ms = exposure_ms
        self.set.append(exposure_ms)

    def grab(self, timeout_s=5.0):
        self.grabs += 1
        return np.clip(self.scene * self.exposure_ms, 0, 255).astype(np.uint8)


class Head:
    def __init__(self):
        self.offs = 0

    def off(self):
        self.offs += 1


@pytest.mark.parametrize("dn_per_ms", [0.3, 2.0, 60.0])      # dim room, right, glaring
def test_room_light_is_exposed_well_and_the_line_exposure_comes_back(dn_per_ms):
    scene = np.full((64, 64), dn_per_ms)
    scene[20:40, 20:40] *= 0.5
    cam, head = LinearCamera(scene), Head()
    room = grab_room_light(cam, head)
    top = np.percentile(room.image, 99.5) / 255
    assert ACCEPT[0] <= top <= ACCEPT[1] and (room.image == 255).mean() < 0.005
    assert np.isclose(room.exposure_ms * dn_per_ms / 255, top, atol=0.01)   # as taken
    assert head.offs == 1 and cam.exposure_ms == 10.0 and cam.grabs <= 4


def test_the_station_starts_from_the_exposure_the_room_light_needed_last():
    from types import SimpleNamespace

    cam = LinearCamera(np.full((64, 64), 0.3))
    station = SimpleNamespace(devices=SimpleNamespace(camera=cam, head=Head()),
                              room_light_ms=None)
    first = station_room_light(station)
    assert first.grabs >= 2 and station.room_light_ms == first.exposure_ms
    again = station_room_light(station)
    assert again.grabs == 1 and again.exposure_ms == first.exposure_ms
    assert cam.exposure_ms == 10.0


# -- on the simulated rig -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A scan of the step block at binning 4, recorded while the head was left showing a line:
    the ambient frame must have none."""
    out = tmp_path_factory.mktemp("amb") / "rec"
    station = simulated(sim_world("step-block", seed=3, binning=4))
    station.devices.head.show_line(np.array([0.0, -40.0]), np.array([0.0, 40.0]))
    record_scan(station, out, spacing=1.0, region=(-12, 12, -44, 44))
    return Sequence.open(out)


def test_the_recorded_ambient_frame_has_no_line_and_is_well_exposed(recorded):
    seq = recorded
    ambient, frame = seq.read_ambient(), seq.read_frame(len(seq) // 2)
    line = seq.frames[len(seq) // 2].line
    rec = ScanReconstructor(default_rig(seed=3, binning=4).operator.camera, HEAD["pivot_height_mm"])
    a, b = np.array(line.start), np.array(line.end)
    assert rec.add(0, frame, a, b) > 20 and rec.add(1, ambient, a, b) == 0
    assert 0.45 <= np.percentile(ambient, 99.5) / 255 <= 0.9 and seq.ambient.exposure_ms > 10


def test_replay_and_live_scans_give_each_point_its_grey_value(recorded, tmp_path):
    cloud = scan_replay(recorded.folder).cloud
    amb, z = cloud.attributes["ambient"], cloud.points[:, 2]
    assert amb.dtype == np.float32 and len(amb) == len(cloud)
    assert amb[z > 2].mean() > amb[z < 0.5].mean() + 0.15           # the part is brighter
    # the values are the ambient frame's at the pixels the points were measured at (Method 1
    # puts each point on its pixel's ray: projected back, it lands there)
    cam = default_rig(seed=3, binning=4).operator.camera
    uv, _ = cv2.projectPoints(cloud.points, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)
    expect = grey_at(recorded.read_ambient(), uv.reshape(-1, 2))
    assert np.percentile(np.abs(expect - amb), 90) < 0.002
    # a recording without the ambient frame (another recorder's) still reconstructs
    data = json.loads((recorded.folder / "sequence.json").read_text())
    del data["ambient"]
    other = tmp_path / "other"
    shutil.copytree(recorded.folder / "frames", other / "frames")
    (other / "sequence.json").write_text(json.dumps(data))
    plain = scan_replay(other).cloud
    assert "ambient" not in plain.attributes and len(plain) == len(cloud)
    station = simulated(sim_world("step-block", seed=3, binning=4))
    live = scan_live(station, spacing=2.0, region=(-12, 12, -44, 44), exposure_ms=8.0).cloud
    assert live.attributes["ambient"][live.points[:, 2] > 2].mean() > 0.25
    assert station.devices.camera.exposure_ms == 8.0                # the lines' exposure


def test_cloud_picture_has_the_camera_panel_when_the_cloud_has_ambient(recorded, tmp_path):
    cloud = scan_replay(recorded.folder).cloud
    save_cloud_picture(cloud, tmp_path / "both.png", title="rec.ply")
    bare = PointCloud(cloud.points, {"line": cloud.attributes["line"]})
    save_cloud_picture(bare, tmp_path / "height.png")
    both, height = (cv2.imread(str(tmp_path / n)) for n in ("both.png", "height.png"))
    assert both.shape[0] >= 900 and height.shape[0] == both.shape[0]
    assert both.shape[1] > 1.6 * height.shape[1]                       # a second panel
    grey = np.abs(both.astype(int) - both.mean(2, keepdims=True)).max(2) < 3
    assert grey[:, both.shape[1] // 2:].mean() > 0.8    # the camera panel is grey
    assert not grey[:, :height.shape[1] // 2].mean() > 0.8


# -- a damaged recording, as the operator sees it --------------------------------------------
@pytest.mark.parametrize("damage, words", [
    (lambda f: f.write_bytes(f.read_bytes()[:len(f.read_bytes()) // 2]),
     ["00001.png: truncated or damaged PNG", "only"]),
    (lambda f: f.write_bytes(bytes(b ^ 0xFF if i == 60 else b
                                   for i, b in enumerate(f.read_bytes()))),
     ["00001.png: damaged PNG", "CRC mismatch"]),
    (lambda f: (f.parent.parent / "ambient.png").write_bytes(
        (f.parent.parent / "ambient.png").read_bytes()[:-12]),
     ["ambient.png: truncated PNG (no IEND chunk)"]),
    (lambda f: (f.parent.parent / "sequence.json").write_text('{"format": "insitu-seq'),
     ["sequence.json: not valid JSON"]),
])
def test_a_damaged_frame_or_file_is_one_line_without_library_chatter(recorded, tmp_path, damage,
                                                                      words):
    """The whole process's output (C libraries' stderr included): one line naming the file."""
    import subprocess
    import sys

    rec = tmp_path / "rec"
    shutil.copytree(recorded.folder, rec)
    damage(rec / "frames" / "00001.png")
    code = "from insitu.cli.main import main; main()"
    res = subprocess.run([sys.executable, "-c", code, "scan", "--replay", str(rec), "-o",
                          str(tmp_path / "c.ply")], capture_output=True, text=True, timeout=120)
    lines = [ln for ln in (res.stdout + res.stderr).splitlines()
             if not ln.startswith("scanning: ")]                  # plain progress lines
    assert res.returncode == 1 and len(lines) == 1, res.stdout + res.stderr
    assert lines[0].startswith("error: ") and all(w in lines[0] for w in words), lines[0]
    assert not (tmp_path / "c.ply").exists()


def test_a_camera_that_gives_no_room_light_frame_still_scans(monkeypatch, tmp_path):
    """A camera the head triggers gives no frame with the laser off: the scan goes on, its
    points without grey values, and says why."""
    from insitu.errors import DeviceError

    station = simulated(sim_world("step-block", seed=3, binning=4))
    cam, grab = station.devices.camera, station.devices.camera.grab

    def triggered_by_the_head(timeout_s=5.0):
        if station.world.laser.kind == "off":
            raise DeviceError("camera: no frame within 5 s (no trigger from the scan head?)")
        return grab(timeout_s)
    monkeypatch.setattr(cam, "grab", triggered_by_the_head)
    result = scan_live(station, spacing=2.0, region=(-12, 12, -44, 44))
    assert len(result.cloud) > 500 and "ambient" not in result.cloud.attributes
    assert result.summary.ambient.startswith("none (the room-light frame failed: camera: no")
    assert station.world.laser.kind == "off"
    seq = Sequence.open(record_scan(station, tmp_path / "rec", spacing=4.0,
                                    region=(-12, 12, -44, 44)))
    assert seq.ambient is None and not (seq.folder / "ambient.png").exists() and len(seq) == 7


def test_the_camera_panel_is_stretched_to_the_brightest_point(tmp_path):
    """A 12-bit camera's frames fill a 16-bit full scale to 1/16: still readable."""
    x, y = np.meshgrid(np.linspace(-10, 10, 200), np.linspace(-20, 20, 400))
    pts = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    amb = np.where(pts[:, 0] > 0, 0.06, 0.02).astype(np.float32)      # Mono12 in uint16
    save_cloud_picture(PointCloud(pts, {"ambient": amb}), tmp_path / "p.png")
    img = cv2.imread(str(tmp_path / "p.png"), cv2.IMREAD_GRAYSCALE)
    right = img[:, img.shape[1] // 2:]
    assert (right > 230).mean() > 0.1 and ((right > 60) & (right < 110)).mean() > 0.1
