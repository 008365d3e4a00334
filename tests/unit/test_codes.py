"""Codes: Data Matrix / Micro QR / Code 128 / QR sources, sizing without the quiet zone, the
default hatch along the modules, and the verifier that decodes a planned job's own marks."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import segno
import shapely

from insitu.errors import FormatError
from insitu.formats.pointcloud import PointCloud
from insitu.marking import Placement
from insitu.marking.verify import check_code
from insitu.patterns import load_pattern
from insitu.patterns.model import Code
from insitu.services.plan import plan_mark
from insitu.services.scan import scan_replay
from insitu.services.station import connect

DATA = Path(__file__).resolve().parents[1] / "data"
SEGNO = DATA / "vector" / "segno"
GS1 = "(01)09501101530003(21)0042"
SPECS = {"datamatrix": f'datamatrix:"{GS1}"', "microqr": "microqr:12345",
         "code128": "code128:0042", "qr": 'qr:"HELLO WORLD"'}
TEXTS = {"datamatrix": GS1, "microqr": "12345", "code128": "0042", "qr": "HELLO WORLD"}


@pytest.fixture(scope="module")
def station():
    with connect(binning=4) as st:
        yield st


@pytest.fixture(scope="module")
def step_block():
    """The recorded scan of the step block: a flat step at z = 5 mm around (0, -10)."""
    return scan_replay(DATA / "scan-step-block-b4").cloud


def _cylinder(r=15.0):
    xs, ys = np.meshgrid(np.linspace(-20, 20, 161), np.linspace(-20, 20, 161))
    return PointCloud(np.c_[xs.ravel(), ys.ravel(),
                            np.sqrt(np.maximum(r * r - xs.ravel() ** 2, 0)) - r])


def test_code_sources_encode_exactly_and_size_without_quiet_zone():
    dm = load_pattern(SPECS["datamatrix"] + ";module=0.3")
    assert dm.code == Code("datamatrix", GS1, 16, 16, 2)             # GS1, square
    assert dm.size == pytest.approx((20 * 0.3, 20 * 0.3))             # quiet zone in frame
    assert dm.mark_width == pytest.approx(16 * 0.3)
    c128 = load_pattern("code128:SN-0042")
    assert c128.code.quiet == 10 and c128.code.rows == round(0.25 * c128.code.cols)
    qr = load_pattern('qr:"HELLO WORLD"').placed((0, 0), 10.0)
    assert qr.mark_width == pytest.approx(10.0)                      # without its quiet zone
    assert qr.size[0] == pytest.approx(10.0 * 29 / 21)
    with pytest.raises(FormatError, match=r"microqr:.*cannot encode"):
        load_pattern("microqr:" + "x" * 60)
    with pytest.raises(FormatError, match=r"microqr:.*error correction must be one of L, M, Q"):
        load_pattern("microqr:1;ec=H")


def test_default_code_hatch_runs_along_the_modules():
    pl = Placement(SPECS["datamatrix"], (0.0, 0.0), 16 * 0.25, 30.0)
    p = pl.placed()
    spacing, angle = pl.code_hatch(p)
    assert angle == 30.0 and spacing == pytest.approx(0.25 / 5)     # 5 lines per module
    lines = pl.polylines(p)
    hatched = [q for q in lines if not np.allclose(q[0], q[-1])]       # not an outline
    d = np.concatenate([np.diff(q, axis=0) for q in hatched])
    along = np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 180
    step = np.hypot(*d.T)
    # the lines run along the modules; joined back and forth by one spacing straight across
    assert np.allclose(along[step > 1.01 * spacing], 30.0, atol=1e-6)
    across = step <= 1.01 * spacing
    assert np.allclose(along[across], 120.0, atol=1e-6)
    assert np.allclose(step[across], spacing) and across.any()
    assert len(hatched) < 0.5 * (len(d) - across.sum())                 # fewer paths than lines


@pytest.mark.parametrize("rotate", [0.0, 30.0, 90.0])
@pytest.mark.parametrize("kind, module", [(k, m) for k in SPECS for m in (0.25, 0.5)
                                          if (k, m) != ("code128", 0.5)])  # 28 mm > the step
def test_every_code_decodes_from_the_job_on_the_scanned_part(station, step_block, kind,
                                                             rotate, module):
    spec = SPECS[kind] + f";module={module}"
    plan = plan_mark(step_block, Placement(spec, (0.0, -10.0), None, rotate), station.driver)
    (check,) = plan.codes
    assert check.ok and check.decoded == TEXTS[kind]
    assert check.module_mm == pytest.approx(module)


@pytest.mark.parametrize("kind", list(SPECS))
def test_every_code_decodes_wrapped_on_the_arc(station, kind):
    plan = plan_mark(_cylinder(), Placement(SPECS[kind] + ";module=0.25", (2.0, 0.0), None,
                                            15.0, "wrap"), station.driver)
    assert plan.projection.max_stretch < 0.01
    assert plan.codes[0].decoded == TEXTS[kind]


def test_a_code_that_would_not_read_is_refused_unless_forced(station, step_block):
    bad = Placement(SPECS["qr"] + ";module=0.25", (0.0, -10.0), None, hatch_mm=0.6)
    with pytest.raises(FormatError, match=r"qr:HELLO WORLD: does not decode .*nothing written"):
        plan_mark(step_block, bad, station.driver)
    plan = plan_mark(step_block, bad, station.driver, force=True)
    assert not plan.codes[0].ok


def _module(p) -> float:
    """Module size of a placed QR / Micro QR drawing: its top-left finder is 7 modules."""
    x0, y0, x1, y1 = p.bounds()
    row = shapely.LineString([(x0 - 1, y1 - 1e-3), (x1 + 1, y1 - 1e-3)])
    first = shapely.get_parts(p.to_shapely().intersection(row))[0]
    return first.length / 7


@pytest.mark.parametrize("name, text", [
    ("hello.svg", "HELLO WORLD"),                                 # segno's default: strokes
    ("the-beatles-1-q-scale-10-unit-mm.svg", "The Beatles"),
    ("vampire-blues-m4-m-no-border.svg", "Vampire Blues"),
    ("my-vcard.svg", None),
])
def test_segno_svgs_decode_from_the_job(station, step_block, tmp_path, name, text):
    f = SEGNO / name
    if name == "hello.svg":
        f = tmp_path / name
        segno.make_qr("HELLO WORLD").save(str(f))
    pl = Placement(str(f), (0.0, -9.0), 10.0, hatch_mm=0.05)
    plan = plan_mark(step_block, pl, station.driver)
    p = plan.pattern
    m = _module(p)
    x0, y0, x1, y1 = p.bounds()
    n = round((x1 - x0) / m)
    code = Code("microqr" if "m4" in name else "qr", text or "", n, n, 0)
    frame = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    check, _ = check_code(dataclasses.replace(p, code=code, frame=frame),
                          [q.points[:, :2] for q in plan.job.paths], 0.05)
    if text is None:
        assert check.decoded.startswith("BEGIN:VCARD")
    else:
        assert check.decoded == text


def test_a_code_whose_quiet_zone_another_mark_enters_is_refused(station, step_block):
    from insitu.services.plan import plan_placements

    code = Placement(SPECS["datamatrix"] + ";module=0.3", (0.0, -10.0), None)
    near = Placement('text:"A"', (3.2, -10.0), 2.0)     # the symbol ends at x = 2.4, zone 3.0
    far = Placement('text:"A"', (6.0, -10.0), 2.0)
    out = plan_placements(step_block, [code, near], station.driver)
    assert out[0].plan is None and "placement 2's marks enter its quiet zone" in out[0].error
    assert out[1].plan is None and "its marks enter the quiet zone of placement 1" in out[1].error
    assert out[0].where == out[1].where and 2.4 < out[1].where[0] < 3.0   # where they meet
    out = plan_placements(step_block, [code, far], station.driver)
    assert out[0].plan is not None and out[0].plan.codes[0].ok
