"""Read-back on photographs our code did not draw (tests/data/real-codes: zxing-cpp's test
images, Apache-2.0): every code decodes to its known text, and its grade lies in a band the
picture justifies."""

from pathlib import Path

import numpy as np
import pytest
import zxingcpp
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.images import read_image
from insitu.vision.code_photo import read_photo

PHOTOS = Path(__file__).resolve().parents[1] / "data" / "real-codes"

# file: text, (worst, best) overall grade 0 F … 4 A, light marks on a dark ground?
EXPECTED = {
    # a sharp DPM on cast metal, even light: FPD B (one clock module lost in the grain)
    "dm-cast-metal.webp": ("24I44", (3, 4), False),
    "dm-rough-surface.webp": ("W004245700121", (2, 4), False),
    # separate dots, 3.9 px a module on a cylinder: the dots' gaps pull modules toward GT
    "dm-dotted-cylinder.webp": ("A12206200417:02:38", (1, 2), False),
    # blurred, curved, contrast 0.3: decodes, but grades F (a verifier would reject it)
    "dm-vial-blurred.webp": ("(01)08903819987659(21)XY061M5Z9NHXP10R20NN(17)310630"
                             "(10)BNav4Cam2", (0, 0), False),
    "dm-rect-handle.webp": ("1234", (1, 3), False),
    "qr-light-on-dark.webp": ("https://beeline.co/pages/app", (1, 2), True),
    # a sharp print, half in shadow: the threshold follows the light (F before; the
    # contrast the shadow takes still counts: C)
    "qr-half-shadow.webp": ("MECARD:N:Sean Owen;TEL:+12125658770;EMAIL:srowen@google.com;;",
                            (2, 3), False),
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_a_real_photo_decodes_and_grades_within_its_band(name):
    text, (lo, hi), light = EXPECTED[name]
    codes = read_photo(read_image(PHOTOS / name))
    assert [c.text for c in codes] == [text]
    c = codes[0]
    assert lo <= c.overall <= hi, c.grades.summary()
    assert c.grades.inverted == light
    assert c.grades.decode == 4
    # rectified by its corners, the grid is square: axial nonuniformity grades A
    assert c.grades.axial_nonuniformity < 0.06, c.grades.summary()
    assert 0.15 < c.grades.cell_contrast <= 1.0


def test_the_ladder_reads_a_photo_plain_zxing_cannot():
    img = read_image(PHOTOS / "dm-vial-blurred.webp")
    assert zxingcpp.read_barcodes(img) == []
    assert len(read_photo(img)) == 1


@pytest.mark.parametrize("name", ["qr-light-on-dark.webp", "dm-cast-metal.webp",
                                  "dm-dotted-cylinder.webp"])
def test_turning_the_photo_leaves_text_contrast_and_grade(name):
    """zxing-cpp's corners (to the whole pixel) are refined on the modules, and the code is
    read again square-on from its rectified picture: the first read's grid, a fraction of a
    module off on a small symbol, sampled modules wrong with the photo's turn (the Data Matrix
    on cast metal B, D, B, B; the QR C, D, D, C; the dotted one F, D, D, F before)."""
    img = read_image(PHOTOS / name)
    codes = [read_photo(np.ascontiguousarray(np.rot90(img, k)))[0] for k in range(4)]
    assert {c.text for c in codes} == {EXPECTED[name][0]}
    grades = [c.overall for c in codes]
    assert max(grades) - min(grades) <= 1, grades
    cc = [c.grades.cell_contrast for c in codes]
    assert max(cc) - min(cc) < 0.02


def test_inspect_reads_a_photo_without_a_plan(tmp_path):
    out = tmp_path / "codes.png"
    res = CliRunner().invoke(app, ["inspect", str(PHOTOS / "qr-light-on-dark.webp"),
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "beeline" in res.output and "datamatrix" not in res.output
    assert out.is_file() and read_image(out).shape[0] == (29 + 4) * 8
    blank = tmp_path / "blank.png"
    from insitu.services.mark import save_image
    save_image(blank, np.full((60, 80), 200, np.uint8))
    res = CliRunner().invoke(app, ["inspect", str(blank)])
    assert res.exit_code == 1
    assert "no QR, Micro QR or Data Matrix code read" in " ".join(res.output.split())
    res = CliRunner().invoke(app, ["inspect", str(blank), "--at", "1", "2"])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit)
    assert "needs --cloud, --pattern, -o too" in " ".join(res.output.split())


def test_only_a_small_picture_is_enlarged(monkeypatch):
    import cv2

    from insitu.vision import code_decode

    sizes = []
    real = cv2.resize
    monkeypatch.setattr(code_decode.cv2, "resize",
                        lambda img, *a, **k: sizes.append(img.shape) or real(img, *a, **k))
    rng = np.random.default_rng(0)
    assert code_decode.read_codes(rng.integers(0, 255, (120, 90), np.uint8)) == ([], 1.0)
    assert sizes == [(120, 90)]
    sizes.clear()
    wide = rng.integers(0, 255, (40, code_decode.ENLARGE_MAX_PX + 1), np.uint8)
    assert code_decode.read_codes(wide) == ([], 1.0)
    assert sizes == []


def test_a_bent_symbol_is_sampled_on_its_modules():
    """A Data Matrix bent by a wave of 0.6 module across it (a code on a curved part, lens
    distortion): the modules are sampled where the tiles found them, not on the affine grid
    (D without); its grid nonuniformity still says it is bent."""
    import cv2

    from insitu.patterns.codes import zxing_matrix
    from insitu.vision.dpm_grade import grade_symbol

    m = zxing_matrix("datamatrix", "SN 0042 BENT ON A CYLINDER")
    s, q = 8, 2
    flat = np.kron(np.pad(~m, q, constant_values=True).astype(np.float32) * 160 + 40,
                   np.ones((s, s), np.float32))
    yy, xx = np.mgrid[0:flat.shape[0], 0:flat.shape[1]].astype(np.float32)
    wave = 0.6 * s * np.sin(np.pi * (xx / (flat.shape[1] / 2) - 1))
    bent = cv2.remap(flat, xx, yy + wave, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    g = grade_symbol(bent, m, np.full(2, (q + 0.5) * s - 0.5), np.array([s, 0.0]),
                     np.array([0.0, s]), "datamatrix", True)
    assert g.overall >= 3 and g.reflectance_margin == 4, g.summary()
    assert g.grid_nonuniformity > 0.1


def test_a_blurred_grown_mark_reads_sharpened(monkeypatch):
    """A 0.3 mm Data Matrix as the simulated rig's read-back rectifies it (3.8 camera px a
    module through the lens PSF: its light modules small and grey) reads only through the
    sharpened rung of the ladder."""
    from insitu.marking.readback import decode_picture
    from insitu.vision import code_decode

    picture = read_image(PHOTOS.parent / "readback" / "dm-0.3mm-blurred.png", 0)
    assert decode_picture(picture, "datamatrix", 8) == "SN 0000"
    monkeypatch.setattr(code_decode, "SHARPEN", 0.0)
    assert decode_picture(picture, "datamatrix", 8) is None
