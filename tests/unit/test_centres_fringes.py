"""A photograph whose line carries no more laser colour than the colour fringes at its edges is
refused, not measured: a green line across a checkerboard whose white squares clip and whose
edges carry a lens's chromatic aberration (red and blue shifted apart): the blue fringes at
every edge outnumber the line and are taken for it."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.vision.centres import UncertainLine, photo_centres

H, W = 400, 560


def fringed_board(line: float, seed: int = 0, shift: float = 0.6):
    """(photo, laser-off photo) (H, W, 3) uint8 BGR: a checkerboard of 40 px squares, white
    clipped, black 30, the red channel shifted ``shift`` px right and down and the blue as
    far left and up, a green line of ``line`` gray values at row 200 + 0.05 (u − W/2); the
    true row (W,)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    board = np.where(((xx // 40 + (yy - 20) // 40) % 2) == 0, 270.0, 30.0).astype(np.float32)
    board = cv2.GaussianBlur(board, (0, 0), 0.8)
    true = 200 + 0.05 * (np.arange(W) - W / 2)
    stripe = line * np.exp(-0.5 * ((yy - true[None, :]) / 0.8) ** 2)

    def shoot(on):
        chans = [cv2.warpAffine(board, np.float32([[1, 0, d], [0, 1, d]]), (W, H),
                                borderMode=cv2.BORDER_REPLICATE) for d in (-shift, 0.0, shift)]
        chans[1] = chans[1] + on * stripe
        out = [np.clip(c + rng.normal(0, 1.5, c.shape) + 0.5, 0, 255).astype(np.uint8)
               for c in chans]
        return cv2.merge(out)
    return shoot(1.0), shoot(0.0), true


def test_a_line_among_colour_fringes_is_refused():
    bgr, _, _ = fringed_board(150)
    with pytest.raises(UncertainLine, match="colour fringes"):
        photo_centres(bgr, "gray")


@pytest.mark.parametrize("case", ["laser-off frame", "no fringes"])
def test_with_the_laser_off_frame_or_without_fringes_the_line_is_measured(case):
    """With the laser-off frame the fringes go with the scene; a lens without them leaves the
    line the only laser-coloured ridge. Its centres lie on the black squares (on the white
    ones it is clipped away), none wrong (> 5 px off)."""
    bgr, dark, true = fringed_board(150, shift=0.6 if case == "laser-off frame" else 0.0)
    c = photo_centres(bgr, "gray", laser_off=dark if case == "laser-off frame" else None)
    err = np.abs(c.v - true[np.round(c.u).astype(int)])
    assert len(c) > 0.4 * W and (err <= 5).all() and np.median(err) < 0.5


def test_the_command_warns_and_writes_the_others(tmp_path):
    fringed, _, _ = fringed_board(150)
    sharp, _, _ = fringed_board(150, seed=1, shift=0.0)
    cv2.imwrite(str(tmp_path / "fringed.png"), fringed)
    cv2.imwrite(str(tmp_path / "sharp.png"), sharp)
    out = tmp_path / "c.csv"
    res = CliRunner().invoke(app, ["centres", str(tmp_path / "fringed.png"),
                                   str(tmp_path / "sharp.png"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "warning: not measured" in res.output and "colour fringes" in res.output
    files = [r.split(",")[0] for r in out.read_text().splitlines()[1:]]
    assert files and all(f.endswith("sharp.png") for f in files)
    res = CliRunner().invoke(app, ["centres", str(tmp_path / "fringed.png"), "-o",
                                   str(tmp_path / "x.csv")])
    assert res.exit_code == 1 and "colour fringes" in res.output
    assert not (tmp_path / "x.csv").exists()
