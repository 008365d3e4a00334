"""Line centres on frames like real photographs: a thin line on a bright checkerboard, colour
input, a bright sloping background under the line, and the ``insitu centres`` command.

The real photographs themselves (benchmarks/real_lines.py) carry no licence and are not in the
repository; these frames reproduce what broke on them: a white board lifting any global
threshold, a colour JPEG, the board's brightness inside the centroid's window.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.special import ndtr
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.errors import InsituError
from insitu.vision.centres import (
    ImageInputError,
    as_gray,
    gray_centroid,
    line_centres,
    line_direction,
)

H, W = 480, 640


def board(rng, square=34, white=175.0, black=35.0, shape=(H, W)):
    """(H, W) float: a checkerboard (rotated 8°, shifted at random) on a gray room, blurred."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    a = np.radians(8.0)
    x, y = xx * np.cos(a) + yy * np.sin(a), -xx * np.sin(a) + yy * np.cos(a)
    x, y = x + rng.uniform(0, square), y + rng.uniform(0, square)
    checks = ((x // square + y // square) % 2).astype(bool)
    img = np.where(checks, black, white)
    img[:, : shape[1] // 8] = 90.0                               # the room beside the board
    return cv2.GaussianBlur(img, (0, 0), 1.0)


def line(shape, v_of_u, sigma=1.2, amp=60.0):
    """(H, W) pixel-integrated Gaussian line along the rows, centre v_of_u (W,) px."""
    rows = np.arange(shape[0], dtype=np.float64)[:, None]
    s = sigma * np.sqrt(2 * np.pi) * amp
    return s * (ndtr((rows + 0.5 - v_of_u) / sigma) - ndtr((rows - 0.5 - v_of_u) / sigma))


def camera(light, rng, noise=2.0):
    return np.clip(np.round(light + rng.normal(0, noise, light.shape)), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("tilt", [-12.0, 0.0, 12.0])
def test_direction_on_a_bright_checkerboard(seed, tilt):
    """A faint line (60 gray values) on a white board: the top-hat's structure gives the
    direction both ways; the former global threshold (half-way between the median and the
    maximum) saw the board and said "rows" for the vertical line."""
    rng = np.random.default_rng(seed)
    u = np.arange(W, dtype=np.float64)
    v0 = H / 2 + rng.uniform(-60, 60) + np.tan(np.radians(tilt)) * (u - W / 2)
    along_rows = camera(board(rng) + line((H, W), v0), rng)
    assert line_direction(along_rows) == "rows"
    v1 = W / 2 + rng.uniform(-120, 120) + np.tan(np.radians(tilt)) * (np.arange(H) - H / 2)
    scene = board(rng)
    down = camera(scene + line((W, H), v1).T, rng)
    assert line_direction(down) == "cols"
    c = line_centres(down, "steger")                       # auto direction: one point per row
    white = cv2.erode((scene > 170).astype(np.uint8), np.ones((17, 17), np.uint8))
    white = white[np.arange(H), np.round(v1).astype(int)] > 0      # on white, ≥ 8 px from edges
    err = np.full(H, np.inf)
    err[np.round(c.v).astype(int)] = c.u - v1[np.round(c.v).astype(int)]
    assert (np.abs(err[white]) < 1).mean() > 0.9       # all, measured; RMS 0.05–0.38 px: the
    assert np.sqrt(np.mean(err[white] ** 2)) < 0.5      # squares' edges bias Steger's window


@pytest.mark.parametrize("laser", ["g", "r", "b"])
def test_colour_input_picks_the_lasers_channel(laser):
    """A BGR frame: the same board in every channel (a little brighter in one that has no
    line), the line in one channel only. auto takes that channel; r/g/b force one. Peaks are
    taken only near laser-coloured light: the colour frame gives the channel's own centres
    where both find the line, and at least as many."""
    rng = np.random.default_rng(3)
    base = board(rng)
    v0 = np.full(W, 200.4)
    i = "bgr".index(laser)
    chans = [camera(base * (1.1 if c == (i + 1) % 3 else 1.0) + (line((H, W), v0) if c == i
                                                               else 0), rng) for c in range(3)]
    bgr = cv2.merge(chans)
    np.testing.assert_array_equal(as_gray(bgr), chans[i])
    np.testing.assert_array_equal(as_gray(bgr, laser), chans[i])
    np.testing.assert_array_equal(as_gray(bgr, "bgr"[(i + 1) % 3]), chans[(i + 1) % 3])
    auto, own = line_centres(bgr, "steger"), line_centres(chans[i], "steger")
    both, a, b = np.intersect1d(auto.u, own.u, return_indices=True)
    assert len(both) > 0.95 * len(own) and len(auto) >= len(own)
    on = (np.abs(own.v[b] - 200.4) < 1) & (np.abs(auto.v[a] - 200.4) < 1)
    assert on.mean() > 0.9
    np.testing.assert_allclose(auto.v[a][on], own.v[b][on], atol=1e-9)
    white = base[200] > 170               # the line on the white squares (on black it is lost)
    found = np.isin(np.arange(W), auto.u.astype(int))
    assert found[white].mean() > 0.9 and np.median(np.abs(auto.v - 200.4)) < 0.1
    np.testing.assert_array_equal(as_gray(bgr[:, :, 1:2]), chans[1])          # (H, W, 1)


@pytest.mark.parametrize("shape", [(H, W, 4), (H, W, 2), (4, H, W, 3), (0, 5), (5,)])
def test_other_shapes_are_refused_in_one_line(shape):
    with pytest.raises(ImageInputError, match=r"^image of shape .*: expected") as e:
        line_centres(np.zeros(shape, np.uint8), "gray")
    assert isinstance(e.value, InsituError) and "\n" not in str(e.value)
    with pytest.raises(ImageInputError, match="channel 'x'"):
        as_gray(np.zeros((5, 5, 3), np.uint8), "x")
    with pytest.raises(ImageInputError, match="direction 'up'"):
        line_centres(np.zeros((5, 5), np.uint8), "gray", "up")


@pytest.mark.parametrize("k", [0.3, 0.5])
def test_gray_centroid_with_background_is_unbiased_on_a_bright_slope(k):
    """A line (amp 80, σ 1.5 px) on a bright background rising 2 gray values/px across it:
    Eq. 7's K = k · g_max lets the background into the window and pulls the centre to the
    brighter side (mean |error| 0.72 px; with weights g − K 1.2–2.2 px); K above the local
    background (linear across the band) with weights g − K keeps only the line (max |error|
    0.045 / 0.086 px at k = 0.3 / 0.5, the sampling's phase bias)."""
    rng = np.random.default_rng(1)
    v0 = 240.0 + 0.7 * np.sin(np.arange(W) / 40.0)
    rows = np.arange(H, dtype=np.float64)[:, None]
    bg = 150 + 2.0 * (rows - v0)
    img = camera(np.clip(bg, 0, None) + line((H, W), v0, 1.5, 80), rng, noise=0.0)
    band = (v0 - 30, v0 + 30)
    paper = gray_centroid(img, k=k, band=band, median=0)
    ours = gray_centroid(img, k=k, band=band, median=0, background=True)
    err = {n: c.v - v0[c.u.astype(int)] for n, c in (("paper", paper), ("ours", ours))}
    assert len(ours) == W and np.abs(err["ours"]).max() < 0.1
    assert np.abs(err["paper"]).mean() > 0.5


runner = CliRunner()


def _frames(tmp_path, rng):
    u = np.arange(W, dtype=np.float64)
    room = 40 + 20 * rng.random((H, W))
    vert = camera(room + line((W, H), 300.0 + 0.05 * (np.arange(H) - H / 2), 1.5, 120).T, rng)
    colour = cv2.merge([camera(room, rng), vert, camera(room, rng)])
    paths = {"line": tmp_path / "line.png", "colour": tmp_path / "colour.jpg",
             "blank": tmp_path / "blank.png", "text": tmp_path / "notes.png"}
    cv2.imwrite(str(paths["line"]), camera(20 + line((H, W), 100 + 0.01 * u, 1.5, 150), rng))
    cv2.imwrite(str(paths["colour"]), colour, [cv2.IMWRITE_JPEG_QUALITY, 95])
    cv2.imwrite(str(paths["blank"]), np.full((H, W), 30, np.uint8))
    paths["text"].write_text("not an image")
    return paths


def test_centres_command_writes_csv_and_previews(tmp_path):
    p = _frames(tmp_path, np.random.default_rng(5))
    out, prev = tmp_path / "c.csv", tmp_path / "prev"
    res = runner.invoke(app, ["centres", str(p["line"]), str(p["colour"]), str(p["blank"]),
                              "--method", "gray", "-o", str(out), "--preview", str(prev)])
    assert res.exit_code == 0, res.output
    assert "no line found in" in res.output and "blank.png" in res.output
    lines = out.read_text().splitlines()
    assert lines[0] == "file,u,v,peak,width,quality"
    rows = [r.split(",") for r in lines[1:]]
    files = [r[0] for r in rows]
    assert files.count(str(p["line"])) > 0.95 * W and files.count(str(p["colour"])) > 0.95 * H
    assert str(p["blank"]) not in files
    uv = np.array([[float(r[1]), float(r[2])] for r in rows if r[0] == str(p["colour"])])
    assert np.abs(uv[:, 0] - (300 + 0.05 * (uv[:, 1] - H / 2))).max() < 0.5   # auto: "cols"
    for name in ("line", "colour", "blank"):
        img = cv2.imread(str(prev / f"{name}.png"))
        assert img is not None and img.shape == (H, W, 3)
    drawn = cv2.imread(str(prev / "line.png"))
    u, v = (round(float(x)) for x in next(r for r in rows if r[0] == str(p["line"]))[1:3])
    assert tuple(drawn[v, u]) == (0, 0, 255)                          # a centre, in red


@pytest.mark.parametrize("bad, message", [
    ("missing", "missing.png: no such image file"),
    ("text", "notes.png: not a readable image"),
    ("blank", "no laser line found in 1 image"),
])
def test_centres_command_refuses_bad_input_in_one_line_and_keeps_the_old_file(
        tmp_path, bad, message):
    p = _frames(tmp_path, np.random.default_rng(6))
    p["missing"] = tmp_path / "missing.png"
    out = tmp_path / "c.csv"
    out.write_text("old")
    args = [str(p["line"])] if bad != "blank" else []
    res = runner.invoke(app, ["centres", *args, str(p[bad]), "-o", str(out)])
    assert res.exit_code == 1 and message in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert out.read_text() == "old"


@pytest.mark.parametrize("args, message", [
    (["--method", "canny"], "--method 'canny': expected 'gray', 'gaussian' or 'steger'"),
    (["--direction", "up"], "--direction 'up'"),
    (["--channel", "ir"], "--channel 'ir'"),
])
def test_centres_command_refuses_bad_options(tmp_path, args, message):
    p = _frames(tmp_path, np.random.default_rng(7))
    res = runner.invoke(app, ["centres", str(p["line"]), "-o", str(tmp_path / "c.csv"), *args])
    assert res.exit_code == 1 and message in res.output and not (tmp_path / "c.csv").exists()
