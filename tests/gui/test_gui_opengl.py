"""The 3-D view in a real OpenGL window (Xvfb + Mesa, the xcb platform, in a child process
because the test session's Qt runs offscreen): the step block's cloud coloured by height
and the projected pattern must be where the camera puts them; the orthographic top view with
camera colours puts the pattern's outline on its projected paths and shows the grid, the
rulers and the colour bar. (The README's docs/gui*.png are made by the same module:
scripts/gui-pictures.sh.) Fails, never skips, without a display: CI must render."""

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from insitu.ui.model import scene_data as sd
from insitu.ui.model.orbit_camera import OrbitCamera

DATA = Path(__file__).parents[1] / "data"
BACKGROUND = np.array([0.14, 0.12, 0.11]) * 255        # BGR of the view's clear colour


@pytest.fixture(scope="module")
def rendered(tmp_path_factory, height_cal_file):
    """One run of the screenshot module: the iso view by height (``view.png``) and the
    orthographic top view with camera colours (``view-1.png``), a text across a step edge."""
    if not os.environ.get("DISPLAY"):
        pytest.fail("no X display: the OpenGL test needs Xvfb + Mesa (run scripts/test.sh)")
    tmp = tmp_path_factory.mktemp("gl")
    cmd = [sys.executable, "-m", "insitu.ui.qt.screenshot", str(tmp / "gui.png"),
           "--replay", str(DATA / "scan-step-block-b4"), "--height-cal",
           str(height_cal_file), "--pattern", 'text:"insitu"', "--at", "0", "20",
           "--width", "16", "--view", "iso",
           "--extra", f"top:camera:{tmp / 'gui-top.png'}", "--view-png", str(tmp / "view.png")]
    env = dict(os.environ, QT_QPA_PLATFORM="xcb")
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return tmp


def _shot(tmp, name) -> tuple[dict, np.ndarray, np.ndarray]:
    info = json.loads((tmp / f"view{name}.json").read_text())
    view = cv2.imread(str(tmp / f"view{name}.png"), cv2.IMREAD_COLOR)
    window = cv2.imread(str(tmp / ("gui.png" if not name else "gui-top.png")), cv2.IMREAD_COLOR)
    return info, view, window


def _camera(info) -> OrbitCamera:
    return OrbitCamera(np.array(info["centre"]), info["distance_mm"], info["azimuth_deg"],
                       info["elevation_deg"], info["fov_deg"], info["ortho"])


def test_the_view_draws_the_cloud_by_height_and_the_projected_pattern(rendered):
    info, img, window = _shot(rendered, "")
    assert info["renderer"]                                   # a real GL context
    assert window.shape[0] >= 700 and window.shape[1] >= 1200
    h, w = img.shape[:2]
    assert (w, h) == (round(info["width"] * info["device_pixel_ratio"]),
                      round(info["height"] * info["device_pixel_ratio"]))
    cam = _camera(info)
    assert not cam.ortho                                      # iso: perspective
    cloud = np.array(info["cloud_points"])

    def pixels(points):
        px = np.round(cam.project(points, w, h)).astype(int)
        ok = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
        assert ok.mean() > 0.95
        return img[px[ok, 1], px[ok, 0]].astype(float)

    bg = np.linalg.norm(img.astype(float) - BACKGROUND, axis=2) < 12
    assert bg.mean() > 0.5                                    # mostly empty background
    on_block = pixels(cloud)
    drawn = np.linalg.norm(on_block - BACKGROUND, axis=1) > 12
    assert drawn.mean() > 0.9                                 # points where the block is
    for lo, hi in ((2.0, 4.0), (9.0, 11.0), (14.0, 16.0)):    # three steps of the block
        sel = (cloud[:, 2] > lo) & (cloud[:, 2] < hi)
        expect = sd.height_colours(np.array([np.median(cloud[sel, 2])]),
                                   tuple(info["z_range"]))[0][::-1] * 255 * info["shade"]
        got = np.median(pixels(cloud[sel]), axis=0)
        # multisampling blends the 2-px points' edges with the background: got = bg + a·(c − bg)
        d = expect - BACKGROUND
        a = float((got - BACKGROUND) @ d / (d @ d))
        assert a > 0.5 and np.linalg.norm(got - BACKGROUND - a * d) < 15, (lo, hi, got, expect)
    # the projected pattern: magenta within a pixel of where its points project, the cloud
    # dimmed under it
    assert info["shade"] == sd.SHADE_UNDER_PENS
    pattern = np.array(info["pattern_points"])
    assert len(pattern) > 50
    colour = np.array(sd.PROJECTED_COLOUR[2::-1]) * 255
    px = np.round(cam.project(pattern, w, h)).astype(int)
    near = [np.min(np.linalg.norm(img[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3) - colour,
                                  axis=1)) < 60 for x, y in px]
    assert np.mean(near) > 0.7


def test_top_view_is_orthographic_with_outline_on_paths_grid_rulers_and_camera_colours(
        rendered):
    info, img, window = _shot(rendered, "-1")
    cam = _camera(info)
    assert cam.ortho and info["camera_colours"]
    h, w = img.shape[:2]
    scale = info["device_pixel_ratio"]
    # the text crosses the 10 → 15 mm step edge: its paths lie on two levels, and the
    # outline (drawn at one height) still lines up with them: the bounding boxes agree
    pattern = np.array(info["pattern_points"])
    assert np.ptp(pattern[:, 2]) > 3.0
    px = cam.project(pattern, info["width"], info["height"])
    outline = cam.project(np.c_[np.array(info["outline_corners"]),
                                np.full(4, info["handle_z"])], info["width"], info["height"])
    assert np.allclose(px.min(0), outline.min(0), atol=2.0)
    assert np.allclose(px.max(0), outline.max(0), atol=2.0)
    # the magenta paths are drawn there
    colour = np.array(sd.PROJECTED_COLOUR[2::-1]) * 255
    magenta = np.linalg.norm(img.astype(float) - colour, axis=2) < 60
    ys, xs = np.nonzero(magenta)
    assert len(xs) > 100
    assert np.allclose([xs.min(), ys.min()], px.min(0) * scale, atol=4)
    assert np.allclose([xs.max(), ys.max()], px.max(0) * scale, atol=4)
    # camera colours: the cloud's pixels are gray (r = g = b), not the height map
    cloud = np.array(info["cloud_points"])
    cpx = np.round(cam.project(cloud, info["width"], info["height"]) * scale).astype(int)
    ok = (cpx[:, 0] >= 0) & (cpx[:, 0] < w) & (cpx[:, 1] >= 0) & (cpx[:, 1] < h)
    on = img[cpx[ok, 1], cpx[ok, 0]].astype(float)
    drawn = on[np.linalg.norm(on - BACKGROUND, axis=1) > 30]
    assert len(drawn) > 100 and np.median(np.ptp(drawn, axis=1)) < 12
    # the grid: a major line (a multiple of 10 × the step) crosses the view as a faint line
    step = info["grid_step_mm"]
    major = 10 ** np.ceil(np.log10(step * 2))
    x_line = np.ceil((info["centre"][0] - 20) / major) * major
    col = int(round(cam.project(np.array([[x_line, info["centre"][1], 0.0]]), info["width"],
                                info["height"])[0, 0] * scale))
    strip = img[h // 4:3 * h // 4, col - 1:col + 2].astype(float)
    lifted = np.linalg.norm(strip - BACKGROUND, axis=2).max(1) > 12
    assert lifted.mean() > 0.5
    # the rulers (a dark band with labels) and the colour bar (camera gray: black → white)
    bar = img[40:200, w - int(20 * scale), :].astype(float).mean(1)
    assert bar[0] > bar[-1] + 100                               # white at the top
    band = img[h - int(10 * scale), :, :].astype(float)
    assert (np.linalg.norm(band - (59, 51, 47), axis=1) < 14).mean() > 0.5     # BGR
    assert info["colour_bar"][0] == "camera"
    # the window picture holds the view with its overlay (the colour bar, the rulers)
    assert window.shape[0] >= 700 and window.shape[1] >= 1200
    x0, y0 = (np.array(info["in_window"]) * scale).astype(int)
    inset = window[y0:y0 + h, x0:x0 + w].astype(float)
    assert np.abs(inset - img).mean() < 2
