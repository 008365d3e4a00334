"""The simulated camera: the line lands where the geometry says; shadows, occlusion, sensor."""

import numpy as np
import pytest

from insitu.errors import SafetyError
from insitu.geometry.beams import line_commands
from insitu.sim.devices import SimCamera, SimScanHead, SimStage
from insitu.sim.render import Renderer
from insitu.sim.rig import default_rig
from insitu.sim.scene import Scene
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld
from insitu.vision.centres import gray_centroid


@pytest.fixture(scope="module")
def rig():
    return default_rig(seed=3, binning=2)


def _true_line(rig, start, end, z):
    """(u, v) of the line start → end drawn by the true beams on the plane z, true camera."""
    o, d = rig.beams.rays(line_commands(start, end, 4000))
    s = (z - o[:, 2]) / d[:, 2]
    uv = rig.camera.project(o + s[:, None] * d)
    return uv[np.argsort(uv[:, 0])]


def _column_centroids(img, half=10):
    H, W = img.shape
    cols = np.nonzero(img.max(axis=0) > 0.2 * img.max())[0]
    row = np.argmax(img[:, cols], axis=0)
    rows = np.clip(row[None, :] + np.arange(-half, half + 1)[:, None], 0, H - 1)
    band = img[rows, cols[None, :]].astype(np.float64)
    return cols, (band * rows).sum(0) / band.sum(0)


@pytest.mark.parametrize("z", [-12.0, 0.0, 9.5])
def test_plane_line_lands_where_geometry_says(rig, z):
    scene = Scene([make_workpiece("plate", top_z=z)])
    img = Renderer(rig, scene, ideal=True).line_frame([12.0, -40.0], [12.0, 40.0], focus_z=z)
    cols, v = _column_centroids(img)
    truth = _true_line(rig, [12.0, -40.0], [12.0, 40.0], z)
    inner = (cols > truth[0, 0] + 8) & (cols < truth[-1, 0] - 8)   # away from the line's ends
    v_true = np.interp(cols[inner], truth[:, 0], truth[:, 1])
    err = v[inner] - v_true
    assert inner.sum() > 300
    assert np.max(np.abs(err)) < 0.05, f"max error {np.max(np.abs(err)):.3f} px"


def test_height_moves_the_line_down_the_image(rig):
    rows = []
    for z in (-10.0, 0.0, 10.0):
        scene = Scene([make_workpiece("plate", top_z=z)])
        img = Renderer(rig, scene, ideal=True).line_frame([0.0, -30.0], [0.0, 30.0], focus_z=z)
        rows.append(_column_centroids(img)[1].mean())
    assert rows[0] < rows[1] < rows[2]
    assert 15 < rows[2] - rows[1] < 60      # ~3 px/mm at binning 2: triangulation works


def test_noisy_frame_is_8bit_with_noise_saturation_and_ambient(rig):
    world = SimWorld(rig, parts=[make_workpiece("step-block")], seed=1)
    cam, head = SimCamera(world), SimScanHead(world)
    head.show_line([0.0, -45.0], [0.0, 45.0])
    a, b = cam.grab(), cam.grab()
    assert a.dtype == np.uint8 and a.shape == (rig.camera.height, rig.camera.width)
    assert not np.array_equal(a, b)                         # shot and read noise
    assert 0 < np.median(a) < 20                            # dark background with ambient light
    cam.set_exposure(60.0)
    lit = cam.grab()
    assert (lit == 255).sum() > 50                          # over-exposed: saturates
    head.off()
    dark = cam.grab()
    assert dark[lit == 255].max() < 160                     # laser off: no line where it was
    assert np.median(dark) < 60                             # 6 × the room light, no more


def test_line_centres_track_the_true_line_on_the_step_block(rig):
    """The noisy frame's gray-centroid centres sit on the true line (speckle: ~0.1–0.3 px)."""
    part = make_workpiece("step-block")
    world = SimWorld(rig, parts=[part], seed=2)
    SimScanHead(world).show_line([5.0, -45.0], [5.0, 45.0])
    img = SimCamera(world).grab()
    c = gray_centroid(img)
    origin, dirs = rig.camera.rays(c.uv)            # true camera: where the surface is seen
    on_top = []
    for h, (y0, y1) in zip((3, 5, 10, 15), ((-40, -20), (-20, 0), (0, 20), (20, 40))):
        s = (h - origin[2]) / dirs[:, 2]
        p = origin + s[:, None] * dirs
        sel = (p[:, 1] > y0 + 1.5) & (p[:, 1] < y1 - 1.5) & (np.abs(p[:, 0] - 5) < 1)
        on_top.append(sel.sum())
    assert min(on_top) > 20, on_top                 # every step's top shows the line


def test_walls_shadow_and_occlude(rig):
    """Behind the 15 mm step, seen from the camera on −x, part of the table line is hidden."""
    part = make_workpiece("step-block")
    seen = Renderer(rig, Scene([make_workpiece("table"), part]), ideal=True)
    bare = Renderer(rig, Scene([make_workpiece("table")]), ideal=True)
    # a line on the table just beyond the block's +x side, along the 15 mm step
    start, end = [13.0, 22.0], [13.0, 38.0]
    lit_bare = bare.line_frame(start, end).sum()
    lit_seen = seen.line_frame(start, end).sum()
    assert lit_seen < 0.2 * lit_bare                # hidden behind the block from the camera


def test_scan_head_refuses_points_outside_the_field(rig):
    head = SimScanHead(SimWorld(rig))
    with pytest.raises(SafetyError, match="outside the field"):
        head.show_line([0.0, -120.0], [0.0, 0.0])
    assert head.world.laser.kind == "off"


def test_stage_moves_the_plate(rig):
    world = SimWorld(rig)
    stage, head, cam = SimStage(world), SimScanHead(world), SimCamera(world)
    head.show_line([0.0, -20.0], [0.0, 20.0])
    rows = []
    for z in (0.0, 10.0):
        stage.move_z(z)
        assert stage.position_z() == z
        rows.append(gray_centroid(cam.grab()).v.mean())
    assert rows[1] - rows[0] > 15


def test_spot_frame_is_a_blob_where_the_beam_lands(rig):
    world = SimWorld(rig, plate_z=0.0)
    SimScanHead(world).show_spot([30.0, -20.0])
    img = SimCamera(world).grab().astype(float)
    v, u = np.unravel_index(np.argmax(img), img.shape)
    land = rig.beams.landing(np.array([[30.0, -20.0]]))[0]
    uv = rig.camera.project(np.array([[land[0], land[1], 0.0]]))[0]
    assert np.hypot(u - uv[0], v - uv[1]) < 3
