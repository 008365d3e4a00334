"""Vector files marked as a renderer draws them: SVG strokes outlined in the element's own
user space (then transformed), content beyond the page clipped with a warning, DXF WIPEOUTs
masking what was drawn before them, and a DXF without units said to be one."""

from __future__ import annotations

from pathlib import Path

import ezdxf
import numpy as np
import pytest
import shapely

from insitu.errors import FormatError
from insitu.patterns import load_pattern

PX = 25.4 / 96  # mm per CSS px (the user unit of a file without a viewBox)
CORPUS = Path(__file__).resolve().parents[1] / "data" / "vector" / "ezdxf"


def _svg(tmp_path, body, size='width="100" height="100"'):
    p = tmp_path / "t.svg"
    p.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" {size}>{body}</svg>')
    return p


# --- SVG strokes under transforms --------------------------------------------------------------

def test_a_stroke_under_a_non_uniform_scale_is_wide_where_it_is_stretched(tmp_path):
    # horizontal: 20 px long × 0.5 px wide; vertical: 5 px long × 2 px wide (butt caps)
    body = ('<g transform="scale(2, 0.5)"><path d="M0,50 H10 M30,20 V30" fill="none" '
            'stroke="black" stroke-width="1"/></g>')
    p = load_pattern(f"{_svg(tmp_path, body)};beam=0.01")
    assert p.to_shapely().area == pytest.approx(20 * PX * PX, rel=1e-9)  # a uniform width: 25
    parts = sorted(shapely.get_parts(p.to_shapely()), key=lambda g: g.bounds[0])
    (x0, y0, x1, y1), (u0, v0, u1, v1) = parts[0].bounds, parts[1].bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((20 * PX, 0.5 * PX), rel=1e-9)
    assert (u1 - u0, v1 - v0) == pytest.approx((2 * PX, 5 * PX), rel=1e-9)


def test_round_caps_and_joins_become_ellipses_under_the_transform(tmp_path):
    body = ('<g transform="scale(4, 1)"><path d="M10,50 L10,50.0001" stroke="black" '
            'stroke-width="10" stroke-linecap="round"/></g>')
    dot = load_pattern(f"{_svg(tmp_path, body)};beam=0.01").to_shapely()
    (x0, y0, x1, y1) = dot.bounds
    assert (x1 - x0, y1 - y0) == pytest.approx((40 * PX, 10 * PX), rel=1e-3)
    assert dot.area == pytest.approx(3.14159 * 20 * 5 * PX * PX, rel=2e-3)   # an ellipse


def test_a_non_scaling_stroke_keeps_its_width_in_page_px(tmp_path):
    body = ('<g transform="scale(2, 0.5)"><path d="M0,50 H10 M30,20 V30" fill="none" '
            'stroke="black" stroke-width="1" vector-effect="non-scaling-stroke"/></g>')
    p = load_pattern(f"{_svg(tmp_path, body)};beam=0.01")
    assert p.to_shapely().area == pytest.approx((20 + 5) * PX * PX, rel=1e-9)
    assert p.stroke_widths == pytest.approx((PX,))


def test_the_beam_decision_uses_the_transformed_width(tmp_path):
    body = ('<g transform="scale(3)"><path d="M0,10 H10" fill="none" stroke="black" '
            'stroke-width="0.1"/></g>')                         # 0.3 px = 0.079 mm on the page
    p = load_pattern(f"{_svg(tmp_path, body)};beam=0.05")
    assert p.stroke_widths == pytest.approx((0.3 * PX,)) and not p.paths and p.contours
    assert len(load_pattern(f"{_svg(tmp_path, body)};beam=0.1").paths) == 1


# --- the page ----------------------------------------------------------------------------------

def test_content_beyond_the_page_is_clipped_with_a_warning(tmp_path):
    body = ('<rect x="80" y="10" width="40" height="10"/>'
            '<path d="M50,90 H150" fill="none" stroke="black" stroke-width="0.05"/>')
    p = load_pattern(_svg(tmp_path, body))
    assert p.to_shapely().area == pytest.approx(20 * 10 * PX * PX, rel=1e-9)
    assert p.bounds()[2] == pytest.approx(100 * PX)
    assert shapely.LineString(p.paths[0]).length == pytest.approx(50 * PX, rel=1e-9)
    warning = [n for n in p.notes if n.startswith("warning: content outside the page")]
    assert len(warning) == 1 and "26.46 × 26.46 mm" in warning[0]
    assert f"{200 * PX * PX:.4g} mm² of fill and {50 * PX:.4g} mm of lines" in warning[0]


def test_the_viewbox_is_the_page_and_content_inside_gives_no_warning(tmp_path):
    size = 'width="20mm" height="10mm" viewBox="-10 -5 20 10"'
    inside = load_pattern(_svg(tmp_path, '<rect x="-10" y="-5" width="20" height="10"/>', size))
    assert inside.size == pytest.approx((20, 10)) and not [n for n in inside.notes
                                                           if n.startswith("warning")]
    left = load_pattern(_svg(tmp_path, '<circle cx="-10" cy="0" r="4"/>', size))
    assert left.to_shapely().area == pytest.approx(3.14159 * 16 / 2, rel=1e-3)   # half of it
    with pytest.raises(FormatError, match=r"t\.svg: everything it draws lies outside its page "
                                          r"\(20 × 10 mm\)$"):
        load_pattern(_svg(tmp_path, '<rect x="30" y="0" width="5" height="5"/>', size))


def test_a_file_without_a_page_is_not_clipped(tmp_path):
    p = load_pattern(_svg(tmp_path, '<rect x="-50" y="-50" width="20" height="20"/>', size=""))
    assert p.to_shapely().area == pytest.approx(400 * PX * PX, rel=1e-9)


def test_what_is_left_out_is_said(tmp_path):
    body = ('<rect width="10" height="10"/><foreignObject x="20" y="20" width="5" height="5">'
            '<p xmlns="http://www.w3.org/1999/xhtml">A</p></foreignObject>')
    notes = load_pattern(_svg(tmp_path, body)).notes
    assert "warning: 1 <foreignObject> element(s) not marked" in notes


# --- DXF ---------------------------------------------------------------------------------------

def test_a_wipeout_masks_what_was_drawn_before_it_only(tmp_path):
    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 4
    msp = doc.modelspace()
    msp.add_hatch().paths.add_polyline_path([(0, 0), (10, 0), (10, 10), (0, 10)])
    msp.add_line((-5, 5), (15, 5))
    msp.add_circle((5, 8), 1.5)                               # cut by the wipeout
    msp.add_circle((1.5, 1.5), 1)                             # beside it: untouched
    msp.add_wipeout([(4, -1), (6, -1), (6, 11), (4, 11)])
    msp.add_line((5, -5), (5, 15))                            # drawn over the wipeout
    doc.saveas(tmp_path / "w.dxf")
    p = load_pattern(tmp_path / "w.dxf")
    assert p.to_shapely().area == pytest.approx(80, rel=1e-9)
    assert "1 WIPEOUT(s) mask what was drawn before them" in p.notes
    mask = shapely.box(4, -1, 6, 11)
    lines = [shapely.LineString(q) for q in p.paths]
    after = [g for g in lines if g.length == pytest.approx(20)]
    assert len(after) == 1 and after[0].intersects(mask)      # the later line crosses it
    before = [g for g in lines if g is not after[0]]
    assert all(mask.intersection(g).length < 1e-9 for g in before)
    total = sum(g.length for g in before)
    circle = 2 * 3.14159265 * 1.5
    cut = 2 * 1.5 * (2 * np.arcsin(1 / 1.5))                  # the arc under the 2 mm band
    assert total == pytest.approx(18 + (circle - cut) + 2 * 3.14159265, rel=2e-3)


def test_the_corpus_wipeout_hides_the_lines_beneath_it():
    path = CORPUS / "wipeout_random.dxf"
    doc = ezdxf.readfile(str(path))
    drawn = shapely.union_all([shapely.LineString([e.dxf.start.vec2, e.dxf.end.vec2])
                               for e in doc.modelspace().query("LINE")])
    (w,) = doc.modelspace().query("WIPEOUT")
    mask = shapely.Polygon([v.vec2 for v in w.boundary_path_wcs()])
    p = load_pattern(path)                                    # $INSUNITS 6: metres → mm
    marked = shapely.union_all([shapely.LineString(q / 1000) for q in p.paths])
    assert marked.intersection(mask.buffer(-1e-6)).length == 0
    assert marked.length == pytest.approx(drawn.difference(mask).length, rel=1e-6)


def test_a_drawing_without_units_and_a_few_units_across_is_said_to_be(tmp_path):
    p = load_pattern(CORPUS / "Leica_Disto_S910.dxf")
    assert p.notes[0] == ("units: none in the file ($INSUNITS unset) → taken as mm "
                          "(;units= to change)")
    (warning,) = [n for n in p.notes if n.startswith("warning:")]
    assert "only 3.164 × 1.031 units" in warning and ";units=m" in warning
    assert not [n for n in load_pattern(f"{CORPUS / 'Leica_Disto_S910.dxf'};units=m").notes
                if n.startswith("warning:")]
    doc = ezdxf.new()                                          # 40 units across: no warning
    doc.header["$INSUNITS"], doc.header["$MEASUREMENT"] = 0, 0
    doc.modelspace().add_line((0, 0), (40, 0))
    doc.saveas(tmp_path / "big.dxf")
    q = load_pattern(tmp_path / "big.dxf")
    assert q.notes[0].startswith("units: none in the file ($INSUNITS unset, $MEASUREMENT "
                                 "imperial) → taken as mm")
    assert not [n for n in q.notes if n.startswith("warning:")]


def test_pattern_show_prints_the_warnings(tmp_path):
    import re

    from typer.testing import CliRunner

    from insitu.cli.main import app

    svg = _svg(tmp_path, '<rect x="80" y="10" width="40" height="10"/>')
    res = CliRunner().invoke(app, ["pattern", "show", str(svg)], env={"COLUMNS": "200"})
    assert res.exit_code == 0 and res.exception is None, res.output
    text = " ".join(re.sub(r"[│┃┌┐└┘├┤┬┴┼─━]", " ", res.output).split())
    assert "warning content outside the page (26.46 × 26.46 mm) clipped" in text


def test_a_tapered_wide_polyline_and_an_attdef_tag(tmp_path):
    doc = ezdxf.new()
    doc.header["$INSUNITS"] = 4
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0, 2, 0), (10, 0)], format="xyse")     # 2 mm wide → 0: a triangle
    msp.add_attdef("SERIAL", (20, 0), "0042", dxfattribs={"height": 2})
    doc.saveas(tmp_path / "a.dxf")
    p = load_pattern(tmp_path / "a.dxf")
    arrow, tag = (shapely.union_all([g for g in shapely.get_parts(p.to_shapely())
                                     if (g.bounds[0] < 15) == left]) for left in (True, False))
    assert arrow.area == pytest.approx(10, rel=1e-9)
    assert tag.bounds[0] == pytest.approx(20, abs=0.5) and 8 < tag.bounds[2] - 20 < 14  # 6 caps
