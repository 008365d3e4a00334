"""Patterns: every source (sample files and known geometry), transforms, and one-line
FormatErrors for every kind of bad input."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import cv2
import ezdxf
import numpy as np
import pytest
import segno
import shapely
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from insitu.errors import FormatError
from insitu.patterns import (
    Pattern,
    fiducial_centres,
    fiducial_grid,
    hatch,
    load_image,
    load_pattern,
    qr_pattern,
    text_pattern,
    to_svg,
)
from insitu.patterns.model import normalised, region
from pattern_shapes import SAMPLES, square_with_hole


def _svg(tmp_path, body, size='width="50mm" height="50mm" viewBox="0 0 50 50"', name="t.svg"):
    p = tmp_path / name
    p.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" {size}>{body}</svg>')
    return p


def _one_line(e: pytest.ExceptionInfo) -> str:
    msg = str(e.value)
    assert msg and "\n" not in msg
    return msg


def _filled(p: Pattern, x, y) -> bool:
    return p.to_shapely().contains(shapely.Point(x, y))



# --- sources -----------------------------------------------------------------------------------

def test_logo_svg_fills_holes_knockout_and_stroke():
    thin = load_pattern(str(SAMPLES / "logo.svg") + ";beam=0.5")
    assert len(thin.paths) == 1 and len(thin.contours) >= 4  # the 0.3 mm wave: a line
    p = load_pattern(str(SAMPLES / "logo.svg"))
    assert not p.paths and p.stroke_widths == pytest.approx((0.3,))  # the wave: an area
    wave = p.to_shapely().difference(thin.to_shapely())
    assert wave.area == pytest.approx(0.3 * shapely.LineString(thin.paths[0]).length, rel=2e-3)
    assert _filled(p, 16, 10) and not _filled(p, 10, 10)     # ring, even-odd hole
    assert _filled(p, 24, 10)                                # the turned square
    assert _filled(p, 32, 4) and not _filled(p, 34, 7)       # triangle, white knock-out dot
    sq = [c for c in p.contours if np.allclose(shapely.Polygon(c).centroid.coords[0], (24, 10))]
    assert len(sq) == 1 and shapely.Polygon(sq[0]).area == pytest.approx(36, rel=1e-9)


def test_svg_rect_exact_bounds_in_mm(tmp_path):
    p = load_pattern(str(_svg(tmp_path, '<rect x="5" y="10" width="10" height="20"/>')))
    assert p.bounds() == pytest.approx((5, 20, 15, 40), abs=1e-9)   # y flipped, page 50 mm
    # user units without a width: px = 1/96 in
    q = load_pattern(str(_svg(tmp_path, '<rect width="96" height="48"/>', size="")))
    assert q.size == pytest.approx((25.4, 12.7), abs=1e-9)
    # viewBox scaling: 100 user units across 20 mm
    r = load_pattern(str(_svg(tmp_path, '<rect width="50" height="50"/>',
                              'width="20mm" height="20mm" viewBox="0 0 100 100"')))
    assert r.size == pytest.approx((10, 10), abs=1e-9)


def test_svg_transforms_and_fill_rules(tmp_path):
    p = load_pattern(str(_svg(tmp_path, '<g transform="translate(25 25) rotate(30) scale(2)">'
                                        '<rect x="-2" y="-1" width="4" height="2"/></g>')))
    assert p.to_shapely().area == pytest.approx(32, rel=1e-9)
    assert p.centre == pytest.approx((25, 25), abs=1e-9)
    d = "M0 0 H20 V20 H0 Z M5 5 H15 V15 H5 Z"  # both squares clockwise on screen
    nz = load_pattern(str(_svg(tmp_path, f'<path d="{d}"/>')))
    eo = load_pattern(str(_svg(tmp_path, f'<path fill-rule="evenodd" d="{d}"/>')))
    assert nz.to_shapely().area == pytest.approx(400) and len(nz.contours) == 1
    assert eo.to_shapely().area == pytest.approx(300) and len(eo.contours) == 2
    ring = load_pattern(str(_svg(tmp_path, '<circle cx="10" cy="10" r="5" fill="none" '
                                           'stroke="black"/>')))        # stroke-width 1 mm
    assert ring.to_shapely().area == pytest.approx(math.pi * (5.5**2 - 4.5**2), rel=1e-3)
    s = load_pattern(str(_svg(tmp_path, '<circle cx="10" cy="10" r="5" fill="none" '
                                        'stroke="black" stroke-width="0.02"/>')))
    assert not s.contours and len(s.paths) == 1
    assert np.allclose(s.paths[0][0], s.paths[0][-1])        # a closed line, not a fill
    assert np.hypot(*(s.paths[0] - (10, 40)).T) == pytest.approx(5, abs=0.003)


def test_part_dxf_outline_chain_circle_hole_area():
    auto = load_pattern(str(SAMPLES / "part.dxf"))
    assert not auto.contours and len(auto.paths) == 3   # outlines, not fills, by default
    assert all(np.allclose(q[0], q[-1]) for q in auto.paths)
    p = load_pattern(str(SAMPLES / "part.dxf") + ";fill=all")
    assert len(p.contours) == 3 and not p.paths    # lines+arc+spline chained, hole, window
    assert p.bounds()[0] == pytest.approx(0) and p.bounds()[2] == pytest.approx(60)
    hole = [c for c in p.contours if np.allclose(c.mean(axis=0), (20, 20), atol=1e-3)]
    assert len(hole) == 1
    assert shapely.Polygon(hole[0]).area == pytest.approx(math.pi * 25, rel=1e-3)
    assert not _filled(p, 20, 20) and not _filled(p, 44, 20) and _filled(p, 5, 5)


def test_dxf_units_text_and_open_paths(tmp_path):
    doc = ezdxf.new(units=ezdxf.units.IN)
    msp = doc.modelspace()
    msp.add_line((0, 0), (1, 0))
    msp.add_arc((0, 0), 1, 10, 80)
    msp.add_text("AB", height=0.5).set_placement((0, 2))
    doc.saveas(tmp_path / "in.dxf")
    p = load_pattern(str(tmp_path / "in.dxf"))
    assert len(p.paths) == 2 and len(p.contours) >= 3        # A has a hole, B two
    line = [q for q in p.paths if len(q) == 2][0]
    assert np.linalg.norm(line[1] - line[0]) == pytest.approx(25.4, rel=1e-9)
    assert p.bounds()[3] == pytest.approx(2 * 25.4 + 0.5 * 25.4, rel=0.05)


def test_qr_png_sample_has_exact_modules():
    p = load_pattern(str(SAMPLES / "qr.png"))               # 10 px/module at 254 dpi
    m = np.array([list(r) for r in segno.make_qr("https://example.com/insitu",
                                                 error="m").matrix]) & 1
    assert p.size == pytest.approx((len(m) + 8,) * 2)       # 1 mm modules + quiet zone
    assert p.to_shapely().area == pytest.approx(m.sum(), rel=1e-12)


@pytest.mark.parametrize("ec", ["L", "M", "Q", "H"])
def test_qr_spec_modules_quiet_zone_and_error_level(ec):
    p = load_pattern(f'qr:"insitu 0042";ec={ec};quiet=2;module=0.5')
    m = np.array([list(r) for r in segno.make_qr("insitu 0042", error=ec.lower(),
                                                 boost_error=False).matrix]) & 1
    n = len(m) + 4
    assert p.bounds() == pytest.approx((0, 0, n * 0.5, n * 0.5))
    assert p.to_shapely().area == pytest.approx(m.sum() * 0.25, rel=1e-12)
    coords = np.concatenate(p.contours) / 0.5
    assert np.allclose(coords, np.round(coords), atol=1e-12)   # corners on the module grid
    inv = load_pattern(f'qr:insitu 0042;ec={ec};quiet=2;invert=1;module=0.5')
    assert inv.to_shapely().area == pytest.approx((n * n - m.sum()) * 0.25, rel=1e-12)


def test_qr_error_level_and_placement_keeps_quiet_zone():
    low, high = qr_pattern("x" * 40, "L"), qr_pattern("x" * 40, "H")
    assert high.size[0] > low.size[0]
    placed = qr_pattern("abc", quiet_zone=4).placed((0, 0), 30)   # the symbol, 21 modules
    assert placed.size == pytest.approx((30 * 29 / 21,) * 2)        # + its quiet zone
    assert placed.to_shapely().bounds == pytest.approx((-15, -15, 15, 15))


def test_text_outlines_and_size():
    p = load_pattern('text:"HELLO"')
    assert len(p.contours) == 6 and not p.paths              # the O has a counter
    assert p.size[1] == pytest.approx(7.29, rel=0.05)        # DejaVu caps: 0.729 em
    assert text_pattern("HELL").size[1] == pytest.approx(7.29, rel=1e-3)
    o = text_pattern("O", size_mm=20)
    assert len(o.contours) == 2 and not _filled(o, *o.centre)   # the counter is a hole
    serif = load_pattern("text:HELLO;font=DejaVu Serif Bold;size=10")
    assert serif.size != pytest.approx(p.size)
    path = load_pattern("text:Hi;font=/usr/share/fonts/truetype/dejavu/DejaVuSansMono.ttf")
    assert path.size[1] > 5
    two = text_pattern("A\nB")
    assert two.size[1] > 15


def test_fiducial_grid_centres_and_sample():
    g = fiducial_grid(3, 4, pitch_mm=5, diameter_mm=1)
    cents = np.array([c.mean(axis=0) for c in g.contours])
    assert np.allclose(cents, fiducial_centres(3, 4, 5), atol=1e-9)
    assert all(shapely.Polygon(c).area == pytest.approx(math.pi / 4, rel=1e-3)
               for c in g.contours)
    rings = fiducial_grid(2, 2, filled=False)
    assert not rings.contours and len(rings.paths) == 4
    s = load_pattern(str(SAMPLES / "fiducials.svg"))
    assert len(s.contours) == 25 and s.size == pytest.approx((21, 21), abs=1e-9)


def test_raster_modes_and_scale(tmp_path):
    img = np.full((20, 40), 255, np.uint8)
    img[5:10, 10:30] = 0                                      # a 20 × 5 px black bar
    img[12:18, 0:40] = 128                                    # a gray band
    cv2.imwrite(str(tmp_path / "a.png"), img)
    fill = load_image(tmp_path / "a.png", width_mm=40)       # 1 mm pixels
    assert fill.to_shapely().area == pytest.approx(100)
    assert fill.bounds() == pytest.approx((0, 0, 40, 20))     # the frame: the whole image
    assert _filled(fill, 20, 12.5) and not _filled(fill, 20, 5)   # row 5..10 → y 10..15
    lines = load_pattern(f"{tmp_path / 'a.png'};mode=threshold;dpi=25.4")
    assert len(lines.paths) == 5 and all(len(q) == 2 for q in lines.paths)
    assert {round(abs(q[1, 0] - q[0, 0]), 9) for q in lines.paths} == {20.0}
    dots = load_image(tmp_path / "a.png", dpi=25.4, mode="dither")
    lit = sum(abs(q[1, 0] - q[0, 0]) for q in dots.paths)
    assert 100 + 0.4 * 240 < lit < 100 + 0.6 * 240            # ~half the gray band
    assert load_image(tmp_path / "a.png", dpi=25.4, invert=True).to_shapely().area == \
        pytest.approx(800 - 100)                              # gray 128 is just light


# --- model and transforms ---------------------------------------------------------------------

def test_pattern_is_frozen_clean_and_transforms():
    p = Pattern(([[0, 0], [4, 0], [4, 2], [0, 2], [0, 0]],), ([[1, 1]], [[0, 5], [1, 5]]), "r")
    assert len(p.contours[0]) == 4 and len(p.paths) == 1    # closing point, 1-point path gone
    assert not p.contours[0].flags.writeable
    with pytest.raises(AttributeError):
        p.name = "x"
    assert p.bounds() == (0, 0, 4, 5) and p.size == (4, 5) and p.centre == (2, 2.5)
    r = p.transformed(rotate_deg=90)
    assert r.size == pytest.approx((5, 4)) and r.centre == pytest.approx((2, 2.5))
    m = p.transformed(mirror_x=True)
    assert m.bounds() == pytest.approx(p.bounds()) and m.paths[0][0, 0] == pytest.approx(4)
    t = p.transformed(translate=(1, -1), scale=2)
    assert t.centre == pytest.approx((3, 1.5)) and t.size == pytest.approx((8, 10))


@pytest.mark.parametrize("spec", ["logo.svg", "part.dxf", "qr.png", 'text:"Ag 42"',
                                  "qr:hello"])
def test_placed_centre_and_width_exact(spec):
    p = load_pattern(str(SAMPLES / spec) if "." in spec else spec)
    q = p.placed((12.5, -7.25), 33.3)
    assert q.centre == pytest.approx((12.5, -7.25), abs=1e-9)
    assert q.mark_width == pytest.approx(33.3, abs=1e-9)     # a code's without quiet zone
    assert q.size[1] == pytest.approx(p.size[1] * 33.3 / p.mark_width, abs=1e-9)
    r = p.placed((1, 2), 20, rotate_deg=90)                  # rotated about the placed centre
    assert r.centre == pytest.approx((1, 2), abs=1e-9)
    assert r.size[1] == pytest.approx(p.size[0] * 20 / p.mark_width, abs=1e-9)


def test_empty_pattern_errors():
    e = Pattern((), (), "nothing")
    assert e.is_empty
    with pytest.raises(FormatError, match="empty") as info:
        e.bounds()
    _one_line(info)
    with pytest.raises(FormatError, match="empty"):
        hatch(e, 0.1)
    with pytest.raises(FormatError):
        Pattern(((0, 0), (0, 1)), (((0, 0), (0, 1)),)).placed((0, 0), 10)   # zero width


def test_regions_and_svg_round_trip(tmp_path):
    star = np.array([[math.cos(a), math.sin(a)] for a in
                     np.radians(90 + 144 * np.arange(5))]) * 10   # self-crossing pentagram
    assert region([star], "nonzero").area > region([star], "evenodd").area
    assert region(normalised([star], "nonzero"), "evenodd").area == \
        pytest.approx(region([star], "nonzero").area)
    p = square_with_hole()
    f = tmp_path / "h.svg"
    f.write_text(to_svg(p))
    assert load_pattern(str(f)).to_shapely().area == pytest.approx(p.to_shapely().area)


# --- bad input -------------------------------------------------------------------------------

@pytest.mark.parametrize("name,data", [
    ("bad.svg", b"this is not xml at all <<<"),
    ("bad.svg", b'<svg xmlns="http://www.w3.org/2000/svg"><rect width="'),
    ("bad.dxf", b"0\nSECTION\n2\nHEADER\nnonsense\n"),
    ("bad.dxf", b"\x00\x01\x02garbage"),
    ("bad.png", b"\x89PNG\r\n\x1a\n garbage"),
    ("empty.svg", b'<svg xmlns="http://www.w3.org/2000/svg" width="10mm" height="10mm"/>'),
])
def test_garbage_files_raise_one_line_format_error(tmp_path, name, data):
    f = tmp_path / name
    f.write_bytes(data)
    with pytest.raises(FormatError) as info:
        load_pattern(str(f))
    assert name in _one_line(info)


def test_empty_dxf_white_image_and_missing_things(tmp_path):
    ezdxf.new().saveas(tmp_path / "empty.dxf")
    with pytest.raises(FormatError, match="empty") as info:
        load_pattern(str(tmp_path / "empty.dxf"))
    _one_line(info)
    cv2.imwrite(str(tmp_path / "white.png"), np.full((8, 8), 255, np.uint8))
    with pytest.raises(FormatError, match="white.png.*empty"):
        load_pattern(str(tmp_path / "white.png"))
    for spec, match in [(str(tmp_path / "nope.svg"), "nope.svg: no such"),
                        (str(tmp_path / "nope.txt"), "no such"),
                        ('text:"hi";font=No Such Font Family', "No Such Font Family"),
                        ('text:"hi";font=/nowhere/x.ttf', "x.ttf"),
                        ('text:""', "empty"), ('qr:""', "empty"),
                        ('qr:"x";ec=Z', "L, M, Q, H"), ("qr:x;colour=red", "unknown option"),
                        ("text:x;size=big", "size"), ("fiducials:lots", "ROWSxCOLS"),
                        ("text:\u4e00", "no glyph"), ("", "empty")]:
        with pytest.raises(FormatError, match=match) as info:
            load_pattern(spec)
        _one_line(info)
    with pytest.raises(FormatError, match="not installed") as info:
        text_pattern("hi", font="Nonexistent Sans")
    _one_line(info)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=400), suffix=st.sampled_from([".svg", ".dxf", ".png"]),
       prefix=st.sampled_from([b"", b"<svg xmlns='http://www.w3.org/2000/svg'>",
                               b"0\nSECTION\n2\nENTITIES\n0\n"]))
def test_random_bytes_only_ever_raise_format_error(data, suffix, prefix):
    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / f"random{suffix}"
        f.write_bytes(prefix + data)
        try:
            p = load_pattern(str(f))
        except FormatError as e:
            assert "\n" not in str(e) and f.name in str(e)
        else:
            assert not p.is_empty


def test_dxf_entity_of_absurd_size_is_refused_quickly(tmp_path):
    import time

    import ezdxf
    doc = ezdxf.new()
    doc.modelspace().add_circle((0, 0), 1e300)
    doc.saveas(tmp_path / "huge.dxf")
    t = time.perf_counter()
    with pytest.raises(FormatError, match=r"huge\.dxf: CIRCLE #\w+ has coordinates that .* beyond"):
        load_pattern(tmp_path / "huge.dxf")
    assert time.perf_counter() - t < 2.0


def test_svg_shape_of_absurd_size_is_refused(tmp_path):
    (tmp_path / "huge.svg").write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="10mm" height="10mm" viewBox="0 0 10 10">'
        '<rect x="0" y="0" width="1e300" height="5" fill="black"/></svg>')
    with pytest.raises(FormatError, match=r"huge\.svg: <rect> #1 has coordinates that .* beyond"):
        load_pattern(tmp_path / "huge.svg")
