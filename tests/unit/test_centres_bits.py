"""Bit depth: every threshold of the centres is a fraction of the frame's full scale, from its
``pixel_bits`` (a recording's, formats.md; a camera's pixel format). A recording re-scaled to
Mono10, Mono12 and Mono16 (values 0 … 2^bits − 1 in 16-bit PNG, as such a camera delivers them)
measures as its 8-bit twin; without ``pixel_bits`` a Mono12 frame is read as 16-bit and its
line, at a sixteenth of that full scale, is not found at all.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats.sequence import Sequence
from insitu.formats.sequence_writer import SequenceWriter
from insitu.services import load_height_calibration, scan_replay
from insitu.sim.workpieces import make_workpiece
from insitu.vision.centres import ImageInputError, line_centres
from insitu.vision.extract import CentreSettings, extract_centres

DATA = Path(__file__).parents[1] / "data"
SCAN, CAL = DATA / "scan-step-block-b2", DATA / "height-cal-b2.json"


def rescaled(img: np.ndarray, bits: int) -> np.ndarray:
    """An 8-bit frame as a ``bits``-bit camera would deliver it: uint16, 0 … 2^bits − 1."""
    return np.round(img.astype(np.float64) * (2 ** bits - 1) / 255).astype(np.uint16)


def top_rms(cloud) -> float:
    """RMS height error (mm) over the step block's tops ≥ 1 mm from its walls."""
    part, p = make_workpiece("step-block"), cloud.points
    z = part.height(p[:, 0], p[:, 1])
    ok = np.isfinite(z)
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        zn = part.height(p[:, 0] + dx, p[:, 1] + dy)
        ok &= np.isfinite(zn) & (np.abs(zn - z) < 0.35)
    return float(np.sqrt(np.mean((p[ok, 2] - z[ok]) ** 2)))


def recording_at(tmp_path: Path, bits: int | None, declare: bool = True) -> Path:
    """The committed binning-2 scan, its frames re-scaled to ``bits`` (None: as recorded)."""
    out = tmp_path / f"scan-{bits}"
    shutil.copytree(SCAN, out)
    if bits is None:
        return out
    spec = json.loads((out / "sequence.json").read_text())
    for f in spec["frames"]:
        img = cv2.imread(str(out / f["file"]), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(out / f["file"]), rescaled(img, bits))
    if declare:
        spec["pixel_bits"] = bits
    (out / "sequence.json").write_text(json.dumps(spec))
    return out


@pytest.fixture(scope="module")
def eight_bit_rms(tmp_path_factory):
    cal = load_height_calibration(CAL)
    return cal, top_rms(scan_replay(recording_at(tmp_path_factory.mktemp("b8"), None),
                                    cal).cloud)


@pytest.mark.parametrize("bits", [10, 12, 16])
def test_a_scan_recorded_at_more_bits_measures_as_its_8_bit_twin(tmp_path, eight_bit_rms,
                                                                 bits):
    cal, rms8 = eight_bit_rms
    rms = top_rms(scan_replay(recording_at(tmp_path, bits), cal).cloud)
    assert abs(rms / rms8 - 1) <= 0.05, (bits, rms, rms8)


def test_frames_give_the_same_centres_at_every_depth():
    """One frame of the recording at 8, 10, 12 and 16 bits: the same centres within 0.01 px
    (the re-scaling rounds), the same columns; 12-bit values read as 16-bit: none."""
    img = Sequence.open(SCAN).read_frame(3)
    ref = extract_centres(img, CentreSettings(smooth_half_window=0))
    assert len(ref) > 500
    for bits in (10, 12, 16):
        c = extract_centres(rescaled(img, bits), CentreSettings(smooth_half_window=0),
                            pixel_bits=bits)
        both, a, b = np.intersect1d(ref.u, c.u, return_indices=True)
        assert len(both) >= 0.99 * len(ref) and len(c) <= 1.01 * len(ref), bits
        assert np.abs(ref.v[a] - c.v[b]).max() < 0.01, bits
        assert c.full_scale == 2 ** bits - 1
        same = np.abs(c.contrast[b] / c.full_scale - ref.contrast[a] / 255) < 0.01
        assert same.mean() > 0.99, bits                   # quality: a fraction of full scale
    assert len(extract_centres(rescaled(img, 12), CentreSettings(smooth_half_window=0))) == 0


def test_a_clipped_line_is_a_plateau_at_the_declared_full_scale():
    """A Mono12 frame clips at 4095: those columns are saturated, centred from their flanks."""
    rows = np.arange(200, dtype=np.float64)[:, None]
    v0 = 100.3 + 0.02 * np.arange(300)
    light = 60 + 9000 * np.exp(-0.5 * ((rows - v0) / 1.6) ** 2)
    img = np.clip(np.round(light), 0, 4095).astype(np.uint16)
    for method in ("gaussian", "steger"):
        c = line_centres(img, method, "rows", pixel_bits=12)
        assert len(c) == 300 and c.saturated.all(), method
        assert np.abs(c.v - v0[c.u.astype(int)]).max() < 0.05, method


def test_pixel_bits_are_written_read_and_checked(tmp_path):
    seq = Sequence.open(recording_at(tmp_path, 12))
    assert seq.pixel_bits == 12 and seq.read_frame(0).max() <= 4095
    bad = recording_at(tmp_path / "over", 10, declare=False)
    spec = json.loads((bad / "sequence.json").read_text())
    spec["pixel_bits"] = 8
    (bad / "sequence.json").write_text(json.dumps(spec))
    with pytest.raises(FormatError, match=r"frames/00000.png: a uint16 image .* pixel_bits is 8"):
        Sequence.open(bad).read_frame(0)
    spec["pixel_bits"] = 9
    (bad / "sequence.json").write_text(json.dumps(spec))
    with pytest.raises(FormatError, match="pixel_bits"):
        Sequence.open(bad)
    src = Sequence.open(SCAN)
    with SequenceWriter(tmp_path / "w", "scan", src.scan_head, src.camera,
                        pixel_bits=12) as w:
        w.add(rescaled(src.read_frame(0), 12), line=src.frames[0].line)
    assert Sequence.open(tmp_path / "w").pixel_bits == 12
    with pytest.raises(FormatError, match="pixel_bits is 10"), \
            SequenceWriter(tmp_path / "x", "scan", src.scan_head, src.camera,
                           pixel_bits=10) as w:
        w.add(rescaled(src.read_frame(0), 12), line=src.frames[0].line)
    assert not (tmp_path / "x").exists()
    with pytest.raises(ImageInputError, match="pixel_bits 12: the image holds 65535"):
        line_centres(np.full((20, 30), 65535, np.uint16), "steger", pixel_bits=12)
