"""The 3-D view in a real OpenGL window (Xvfb + Mesa, the xcb platform, in a child process
because the test session's Qt runs offscreen): the step block's cloud coloured by height
and the projected pattern must be where the camera puts them. (The README's docs/gui.png is
made by the same module: see its docstring.) Fails, never skips, without a display: CI must
render. And the renderer's budget: a moving view draws a thinned cloud."""

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


def _render(tmp_path) -> tuple[dict, np.ndarray, np.ndarray]:
    if not os.environ.get("DISPLAY"):
        pytest.fail("no X display: the OpenGL test needs Xvfb + Mesa (run scripts/test.sh)")
    view_png = tmp_path / "view.png"
    cmd = [sys.executable, "-m", "insitu.ui.qt.screenshot", str(tmp_path / "gui.png"),
           "--replay", str(DATA / "scan-step-block-b4"), "--height-cal",
           str(DATA / "height-cal-b4"), "--pattern", 'text:"insitu"', "--at", "0", "28",
           "--width", "16", "--view", "iso", "--view-png", str(view_png)]
    env = dict(os.environ, QT_QPA_PLATFORM="xcb")
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stderr[-2000:]
    info = json.loads(view_png.with_suffix(".json").read_text())
    view = cv2.imread(str(view_png), cv2.IMREAD_COLOR)
    window = cv2.imread(str(tmp_path / "gui.png"), cv2.IMREAD_COLOR)
    return info, view, window


def test_the_view_draws_the_cloud_by_height_and_the_projected_pattern(tmp_path):
    info, img, window = _render(tmp_path)
    assert info["renderer"]                                   # a real GL context
    assert window.shape[0] >= 700 and window.shape[1] >= 1200
    h, w = img.shape[:2]
    assert (w, h) == (round(info["width"] * info["device_pixel_ratio"]),
                      round(info["height"] * info["device_pixel_ratio"]))
    cam = OrbitCamera(np.array(info["centre"]), info["distance_mm"], info["azimuth_deg"],
                      info["elevation_deg"], info["fov_deg"])
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
                                   tuple(info["z_range"]))[0][::-1] * 255
        got = np.median(pixels(cloud[sel]), axis=0)
        # multisampling blends the 2-px points' edges with the background: got = bg + a·(c − bg)
        d = expect - BACKGROUND
        a = float((got - BACKGROUND) @ d / (d @ d))
        assert a > 0.5 and np.linalg.norm(got - BACKGROUND - a * d) < 15, (lo, hi, got, expect)
    # the projected pattern: magenta within a pixel of where its points project
    pattern = np.array(info["pattern_points"])
    assert len(pattern) > 50
    colour = np.array(sd.PROJECTED_COLOUR[2::-1]) * 255
    px = np.round(cam.project(pattern, w, h)).astype(int)
    near = [np.min(np.linalg.norm(img[y - 1:y + 2, x - 1:x + 2].reshape(-1, 3) - colour,
                                  axis=1)) < 60 for x, y in px]
    assert np.mean(near) > 0.7


def test_a_moving_view_draws_a_thinned_cloud():
    from insitu.ui.qt.gl_renderer import INTERACTIVE_POINTS, Renderer

    r = Renderer()
    r.points.set(np.random.default_rng(1).normal(size=(1_000_000, 3)))
    assert r._cloud(fast=False) is r.points
    thin = r._cloud(fast=True)
    assert INTERACTIVE_POINTS / 2 < thin.count <= INTERACTIVE_POINTS
    k = -(-1_000_000 // INTERACTIVE_POINTS)                # every k-th point, in order
    assert np.array_equal(thin.data[1], r.points.data[k])
    count = thin.count
    r.points.set(np.ones((1_000_000 + k, 3)))              # a new cloud is thinned anew
    assert r._cloud(fast=True) is thin and thin.count == count + 1 and (thin.data == 1).all()
