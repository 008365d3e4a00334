"""Line centres on a hard colour photograph drawn from our simulator: a red stripe whose core
clips white in all three channels on a bright checkerboard, with a red halo, in a room with a
lamp, the edge of a bright cupboard, two thin bright cables, a glossy floor that mirrors the
stripe and a shiny panel that reflects it, under warm room light; JPEG-compressed (chroma at
half resolution). The truth: the stripe's centre in the simulator's ideal frame (geometry
alone). Scored as benchmarks/real_lines.py scores real photographs: found / wrong (> 5 px)
over the columns where the stripe crosses the board, and each method's RMS error against a
naive centre of mass's on the columns both found.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.sim.board import board_on_plate
from insitu.sim.checkerboard import render_checkerboard
from insitu.sim.render import Renderer
from insitu.sim.rig import default_rig
from insitu.sim.scene import Scene
from insitu.sim.world import SimWorld
from insitu.vision.centres import CENTRE_METHODS, line_centres, photo_centres

COLS, ROWS, SQUARE = 9, 7, 10.0


def _disc(shape, centre, radius, soft=2.0):
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    r = np.hypot(xx - centre[0], yy - centre[1])
    return np.clip((radius - r) / soft + 0.5, 0, 1).astype(np.float32)


def _band(shape, p0, p1, half, soft=1.0):
    """Soft band of half-width ``half`` px along the segment p0 → p1."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float32)
    d = np.asarray(p1, np.float32) - p0
    t = np.clip(((xx - p0[0]) * d[0] + (yy - p0[1]) * d[1]) / (d @ d), 0, 1)
    dist = np.hypot(xx - p0[0] - t * d[0], yy - p0[1] - t * d[1])
    return np.clip((half - dist) / soft + 0.5, 0, 1)


def hard_photo(seed: int = 0, jpeg: bool = True):
    """(photo, laser-off photo) (H, W, 3) uint8 BGR, JPEG-decoded (``jpeg``); the true centre
    row per column (W,) (NaN where the stripe is not on the board's white face)."""
    rig = default_rig(seed=0, binning=2)
    cam, rng = rig.camera, np.random.default_rng(seed)
    R_wb, t_wb = board_on_plate(COLS, ROWS, SQUARE, rng)
    R_cb, t_cb = cam.R @ R_wb, cam.R @ t_wb + cam.t
    room = render_checkerboard(cam, R_cb, t_cb, COLS, ROWS, SQUARE, rng).astype(np.float32)
    H, W = room.shape
    x = rng.uniform(-6, 6)
    ideal = Renderer(rig, Scene(SimWorld(rig).scene_parts(), seed=0),
                     ideal=True).line_frame([x, -90.0], [x, 90.0])
    # the true centre per column, and where it lies on the board's face
    rows = np.arange(H, dtype=np.float64)[:, None]
    weight = ideal.astype(np.float64)
    total = weight.sum(axis=0)
    true = (weight * rows).sum(axis=0) / np.maximum(total, 1e-9)
    cols = np.arange(W)
    vi = np.clip(np.round(true).astype(int), 0, H - 1)
    face = (room[vi, cols] > 60) | (cv2.erode(room, np.ones((1, 41), np.uint8))[vi, cols] > 60)
    board = cv2.erode((cv2.GaussianBlur(room, (0, 0), 6) > 45).astype(np.uint8),
                      np.ones((15, 15), np.uint8))[vi, cols] > 0
    true[(total < 0.2 * total.max()) | ~board | ~face] = np.nan
    # room light: the board made bright, a warm cast, clutter
    white = room * 1.15
    clutter = np.zeros((H, W), np.float32)
    top = int(np.nanmin(true)) - 260
    clutter += 255 * _disc((H, W), (W * 0.18, max(top, 60)), 45)                # a lamp
    cupboard = np.zeros((H, W), np.float32)
    cupboard[:, int(W * 0.86):] = 225                                           # its edge
    cables = 210 * np.maximum(_band((H, W), (W * 0.3, 0), (W * 0.42, H), 1.5),
                              _band((H, W), (W * 0.62, 0), (W * 0.55, H), 1.2))
    scene = np.maximum(white, np.maximum(clutter, np.maximum(cupboard, cables)))
    # the laser: a core far above full scale where the board is white, a halo, crosstalk
    refl = np.clip(cv2.GaussianBlur(room, (0, 0), 1.0) / np.percentile(room, 99.0), 0.04, 1)
    core = ideal / ideal.max() * 9.0 * 255 * refl
    halo = cv2.GaussianBlur(core, (0, 0), 5.0) * 0.35
    mirror = np.zeros_like(core)                       # the glossy floor below the board
    shift = int(np.nanmax(true) - np.nanmin(true)) + 150
    mirror[shift:] = cv2.GaussianBlur(core, (0, 0), 3.0)[:-shift] * 0.08
    panel = np.zeros_like(core)                        # a shiny panel beside the board
    panel[:, : int(W * 0.12)] = cv2.GaussianBlur(core, (0, 0), 4.0)[:, : int(W * 0.12)] * 0.3
    laser = core + halo + mirror + panel

    def shoot(on: bool):
        light = laser if on else 0 * laser
        chans = (0.88 * scene + 0.06 * light, 0.97 * scene + 0.10 * light, scene + light)
        out = []
        for c in chans:
            noisy = c + rng.normal(0, 1.0, c.shape) * np.sqrt(np.maximum(c, 0) / 6 + 2)
            out.append(np.clip(noisy + 0.5, 0, 255).astype(np.uint8))
        if not jpeg:
            return cv2.merge(out)
        ok, jpg = cv2.imencode(".jpg", cv2.merge(out), [cv2.IMWRITE_JPEG_QUALITY, 90])
        return cv2.imdecode(jpg, cv2.IMREAD_COLOR)

    return shoot(True), shoot(False), true


@pytest.fixture(scope="module")
def photo():
    return hard_photo(0)


def naive_com(channel: np.ndarray, fraction: float = 0.8, half: int = 8) -> np.ndarray:
    """Per column: the centre of mass of the pixels within ±half rows of the column's
    maximum that reach ``fraction`` of it (benchmarks/real_lines.py's baseline)."""
    g = channel.astype(np.float64)
    peak = np.argmax(g, axis=0)
    rows = np.clip(peak[None, :] + np.arange(-half, half + 1)[:, None], 0, g.shape[0] - 1)
    vals = g[rows, np.arange(g.shape[1])[None, :]]
    vals[vals < fraction * vals.max(axis=0)] = 0
    return (vals * rows).sum(axis=0) / np.maximum(vals.sum(axis=0), 1e-9)


def score(c, true):
    """found, wrong (fractions of the board's columns) and the errors (W,) (NaN: none)."""
    err = np.full(len(true), np.nan)
    u = np.round(c.u).astype(int)
    err[u] = c.v - true[u]
    on = np.isfinite(true)
    got = on & np.isfinite(err)
    right = got & (np.abs(np.nan_to_num(err)) <= 5)
    return right.sum() / on.sum(), (got & ~right).sum() / on.sum(), np.where(right, err, np.nan)


@pytest.mark.parametrize("off", [False, True], ids=["photo", "laser-off subtracted"])
@pytest.mark.parametrize("method", list(CENTRE_METHODS))
def test_the_stripe_is_found_on_a_bright_board_in_a_cluttered_room(photo, method, off):
    bgr, dark, true = photo
    c = photo_centres(bgr, method, laser_off=dark if off else None)
    found, wrong, err = score(c, true)
    naive = naive_com(bgr[:, :, 2]) - true
    both = np.isfinite(err) & (np.abs(np.nan_to_num(naive, nan=99)) <= 5)
    rms, rms_naive = (float(np.sqrt(np.mean(e[both] ** 2))) for e in (err, naive))
    assert found >= 0.9 and wrong <= 0.01, (found, wrong)
    assert both.sum() > 0.5 * np.isfinite(true).sum()
    assert rms <= 0.9 * rms_naive, (rms, rms_naive)


def test_without_the_lasers_colour_the_clutter_wins(photo):
    """What the colour does: the red channel alone, searched as a monochrome frame, finds
    the stripe in far fewer of the board's columns (its clipped core barely stands above the
    white board there, the clutter stands high)."""
    bgr, _, true = photo
    found, wrong, _ = score(line_centres(np.ascontiguousarray(bgr[:, :, 2]), "steger"), true)
    assert found < 0.8 or wrong > 0.05


@pytest.mark.parametrize("method", ["gaussian", "steger"])
def test_a_clipped_core_is_centred_from_its_flanks(method):
    """The photograph as the camera gave it (no JPEG): the core clipped white in all three
    channels is the stripe, centred from its plateau and flanks, not refused as "no peak"."""
    bgr, _, true = hard_photo(0, jpeg=False)
    c = photo_centres(bgr, method)
    found, _, err = score(c, true)
    sat = np.zeros(len(true), bool)
    sat[np.round(c.u[c.saturated]).astype(int)] = True
    clipped = sat & np.isfinite(err)
    assert clipped.sum() > 0.5 * np.isfinite(true).sum()
    assert np.sqrt(np.nanmean(err[clipped] ** 2)) < 0.5


runner = CliRunner()


def test_centres_command_takes_a_laser_off_frame_and_the_bits(photo, tmp_path):
    """``insitu centres`` as a user runs it: the JPEG with --background (the laser-off
    photograph) finds the stripe on the board; a 12-bit frame needs --pixel-bits 12; a
    laser-off frame of another size and unknown bits are refused in one line."""
    bgr, dark, true = photo
    cv2.imwrite(str(tmp_path / "on.png"), bgr)
    cv2.imwrite(str(tmp_path / "off.png"), dark)
    out = tmp_path / "c.csv"
    res = runner.invoke(app, ["centres", str(tmp_path / "on.png"), "--background",
                              str(tmp_path / "off.png"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    uv = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(1, 2))
    u = np.round(uv[:, 0]).astype(int)
    err = np.full(len(true), np.nan)
    err[u] = uv[:, 1] - true[u]
    on = np.isfinite(true)
    assert (np.abs(err[on]) <= 5).mean() >= 0.9
    mono = np.round(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY) * (4095 / 255)).astype(np.uint16)
    cv2.imwrite(str(tmp_path / "mono12.png"), mono)
    args = ["centres", str(tmp_path / "mono12.png"), "-o", str(tmp_path / "m.csv")]
    assert "no laser line found" in runner.invoke(app, args).output
    res = runner.invoke(app, [*args, "--pixel-bits", "12"])
    assert res.exit_code == 0 and len((tmp_path / "m.csv").read_text().splitlines()) > 300
    cv2.imwrite(str(tmp_path / "small.png"), dark[:100])
    for extra, message in ((["--background", str(tmp_path / "small.png")],
                            "--background"), (["--pixel-bits", "9"], "--pixel-bits 9")):
        res = runner.invoke(app, ["centres", str(tmp_path / "on.png"), "-o",
                                  str(tmp_path / "x.csv"), *extra])
        assert res.exit_code == 1 and message in res.output and not (tmp_path / "x.csv").exists()
        assert len(res.output.strip().splitlines()) == 1
