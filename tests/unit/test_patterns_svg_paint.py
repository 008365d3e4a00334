"""SVG painted as a browser paints it: paint servers, opacity and masks by what they look
like (thresholded or dithered, one warning per element whose shades are lost), clip paths as
geometry, use/symbol viewports, markers, dashes, display/visibility, CSS classes, text
outlined with its font (also along a path and flowed), .svgz, many clones of one tile fast."""

from __future__ import annotations

import gzip
import time

import pytest
import shapely

from insitu.patterns import load_pattern, text_pattern

PX = 25.4 / 96  # mm per user unit of a file without a viewBox


def _svg(tmp_path, body, name="t.svg", size='width="100" height="100"'):
    p = tmp_path / name
    p.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" '
                 f'xmlns:xlink="http://www.w3.org/1999/xlink" {size}>{body}</svg>')
    return p


def _area(p) -> float:
    """Marked area in user units² (px²)."""
    return p.to_shapely().area / PX ** 2


_GRADIENT = ('<defs><linearGradient id="g"><stop offset="0" stop-color="black"/>'
             '<stop offset="1" stop-color="white"/></linearGradient></defs>'
             '<rect id="shade" x="10" y="10" width="80" height="40" fill="url(#g)"/>')


def test_a_gradient_is_marked_where_it_is_dark_with_one_warning(tmp_path):
    p = load_pattern(_svg(tmp_path, _GRADIENT))
    assert _area(p) == pytest.approx(40 * 40, rel=0.02)         # black → white: the dark half
    x0, _, x1, _ = p.bounds()
    assert (x0 / PX, x1 / PX) == pytest.approx((10, 50), abs=0.5)
    warnings = [n for n in p.notes if n.startswith("warning:")]
    assert len(warnings) == 1 and '<rect id="shade"> (gradient)' in warnings[0]


def test_a_gradient_dithered_is_dots_whose_density_follows_the_shade(tmp_path):
    p = load_pattern(f"{_svg(tmp_path, _GRADIENT)};paint=dither")
    assert not p.contours and p.paths
    length = sum(shapely.LineString(q).length for q in p.paths) / PX
    rows = 40 / (0.05 / PX)                                     # scan lines one beam apart
    assert length / rows == pytest.approx(40, rel=0.05)         # mean darkness ½ of 80 px


def test_a_one_colour_gradient_is_a_flat_paint(tmp_path):
    body = ('<defs><radialGradient id="g"><stop offset="0" stop-color="#000"/>'
            '<stop offset="1" stop-color="#000"/></radialGradient></defs>'
            '<circle cx="50" cy="50" r="20" fill="url(#g)"/>')
    p = load_pattern(_svg(tmp_path, body))
    assert _area(p) == pytest.approx(3.14159265 * 400, rel=1e-3)
    assert not [n for n in p.notes if n.startswith("warning:")]


def test_a_pattern_fill_is_marked_as_its_tiles(tmp_path):
    body = ('<defs><pattern id="stripes" width="10" height="10" patternUnits="userSpaceOnUse">'
            '<rect width="5" height="10" fill="black"/></pattern></defs>'
            '<rect x="0" y="0" width="100" height="50" fill="url(#stripes)"/>')
    assert _area(load_pattern(_svg(tmp_path, body))) == pytest.approx(2500, rel=0.02)


@pytest.mark.parametrize("attrs, marked", [('opacity="0.1"', False), ('opacity="0.9"', True),
                                           ('fill-opacity="0.2"', False),
                                           ('fill="rgba(0,0,0,0.3)"', False)])
def test_opacity_is_painted_over_white(tmp_path, attrs, marked):
    body = f'<rect x="40" y="0" width="20" height="20" fill="red"/><g><rect x="10" y="10" ' \
           f'width="20" height="20" {attrs} {"" if "fill=" in attrs else "fill=" + chr(34) + "black" + chr(34)}/></g>'
    area = _area(load_pattern(_svg(tmp_path, body)))
    assert area == pytest.approx(400 + (400 if marked else 0), rel=0.02)


def test_group_opacity_and_a_mask(tmp_path):
    body = ('<defs><mask id="m"><rect x="0" y="0" width="50" height="100" fill="white"/>'
            '</mask></defs><rect width="100" height="20" mask="url(#m)"/>'
            '<g opacity="0.3"><rect y="50" width="100" height="20"/></g>')
    assert _area(load_pattern(_svg(tmp_path, body))) == pytest.approx(1000, rel=0.02)


def test_a_clip_path_cuts_as_geometry_under_its_clip_rule(tmp_path):
    body = ('<defs><clipPath id="c"><circle cx="50" cy="50" r="30"/></clipPath>'
            '<clipPath id="ring"><path clip-rule="evenodd" d="M10,10 h80 v80 h-80 z '
            'M30,30 h40 v40 h-40 z"/></clipPath></defs>'
            '<rect width="100" height="100" clip-path="url(#c)"/>'
            '<g transform="translate(0,100)"><rect width="100" height="100" '
            'clip-path="url(#ring)"/></g>')
    p = load_pattern(_svg(tmp_path, body, size='width="100" height="200"'))
    assert _area(p) == pytest.approx(3.14159265 * 900 + 6400 - 1600, rel=1e-3)


def test_a_symbol_is_fitted_into_the_use_viewport(tmp_path):
    body = ('<defs><symbol id="s" viewBox="0 0 10 10"><rect width="10" height="10"/></symbol>'
            '</defs><use xlink:href="#s" x="10" y="10" width="40" height="20"/>')
    p = load_pattern(_svg(tmp_path, body))        # meet: 20 × 20, centred in the 40 wide box
    assert _area(p) == pytest.approx(400, rel=1e-6)
    assert p.bounds()[0] / PX == pytest.approx(20, abs=1e-6)


def test_markers_are_drawn_at_the_ends(tmp_path):
    body = ('<defs><marker id="a" markerWidth="4" markerHeight="4" refX="0" refY="2" '
            'orient="auto"><path d="M0,0 L4,2 L0,4 z"/></marker></defs>'
            '<path d="M10,50 L90,50" stroke="black" stroke-width="2" marker-end="url(#a)"/>')
    p = load_pattern(_svg(tmp_path, body))
    assert _area(p) == pytest.approx(80 * 2 + 0.5 * 8 * 8, rel=1e-3)   # the arrow: 8 × 8 px
    assert p.bounds()[2] / PX == pytest.approx(98, abs=1e-6)


def test_a_dashed_stroke_marks_its_dashes(tmp_path):
    body = ('<path d="M0,50 H100" stroke="black" stroke-width="4" stroke-dasharray="10 10" '
            'stroke-dashoffset="5"/>')
    p = load_pattern(_svg(tmp_path, body))
    assert _area(p) == pytest.approx(50 * 4, rel=1e-6)
    assert len(shapely.get_parts(p.to_shapely())) == 6               # 5 + 10·4 + 5


def test_display_visibility_and_css_classes(tmp_path):
    body = ('<style>.hole { fill: white } #big { fill: black } rect.gone { display: none }'
            '</style><rect id="big" width="50" height="50" fill="none"/>'
            '<rect class="hole" x="10" y="10" width="10" height="10" fill="black"/>'
            '<rect class="gone" x="60" width="30" height="30"/>'
            '<g visibility="hidden"><rect x="60" y="60" width="10" height="10"/>'
            '<rect x="80" y="80" width="10" height="10" visibility="visible"/></g>')
    assert _area(load_pattern(_svg(tmp_path, body))) == pytest.approx(2500 - 100 + 100)


def test_text_is_outlined_with_its_font(tmp_path):
    body = '<text x="10" y="50" font-family="DejaVu Sans" font-size="20">Hi 42</text>'
    p = load_pattern(_svg(tmp_path, body))
    ref = text_pattern("Hi 42", font="DejaVu Sans", size_mm=20 * PX)
    assert p.to_shapely().area == pytest.approx(ref.to_shapely().area, rel=1e-3)
    assert p.size == pytest.approx(ref.size, rel=1e-3)
    assert not [n for n in p.notes if n.startswith("warning:")]


def test_a_missing_font_is_named_with_its_fallback(tmp_path):
    body = '<text x="10" y="50" font-family="NoSuchFont, Arial" font-size="20">A</text>'
    p = load_pattern(_svg(tmp_path, body))
    assert p.contours
    assert any("font 'NoSuchFont' is not installed" in n and "DejaVuSans" in n for n in p.notes)


def test_tspans_anchor_and_text_along_a_path(tmp_path):
    body = ('<defs><path id="arc" d="M10,90 L90,90"/></defs>'
            '<text x="50" y="30" text-anchor="middle" font-size="10">ab<tspan dy="10">cd'
            '</tspan></text><text font-size="10"><textPath xlink:href="#arc" '
            'startOffset="20">xyz</textPath></text>')
    p = load_pattern(_svg(tmp_path, body))
    parts = sorted(shapely.get_parts(p.to_shapely()), key=lambda g: -g.bounds[3])
    top = shapely.unary_union([g for g in parts if g.bounds[1] > (100 - 60) * PX])
    assert (top.bounds[0] + top.bounds[2]) / 2 / PX == pytest.approx(50, abs=1.5)
    low = shapely.unary_union([g for g in parts if g.bounds[3] < (100 - 75) * PX])
    assert low.bounds[0] / PX == pytest.approx(30, abs=1.0)   # 10 + startOffset 20


def test_flowed_text_wraps_in_its_frame_which_is_not_marked(tmp_path):
    body = ('<flowRoot font-size="10"><flowRegion><rect x="0" y="0" width="60" height="90"/>'
            '</flowRegion><flowPara>one two three four five six</flowPara></flowRoot>')
    p = load_pattern(_svg(tmp_path, body))
    x0, y0, x1, y1 = (v / PX for v in p.bounds())
    assert x1 <= 60 and (y1 - y0) > 15                         # wrapped: several lines
    assert _area(p) < 0.3 * 60 * (y1 - y0)                      # glyphs, not the frame
    assert any("flowed text" in n for n in p.notes)


def test_svgz_is_read(tmp_path):
    plain = _svg(tmp_path, '<rect width="20" height="10"/>')
    (tmp_path / "t.svgz").write_bytes(gzip.compress(plain.read_bytes()))
    assert _area(load_pattern(tmp_path / "t.svgz")) == pytest.approx(200)


def test_many_clones_of_a_shaded_tile_are_drawn_once(tmp_path):
    tile = ('<defs><linearGradient id="g"><stop offset="0" stop-color="black"/>'
            '<stop offset="1" stop-color="#888"/></linearGradient>'
            '<g id="tile"><circle cx="5" cy="5" r="4" fill="url(#g)"/>'
            '<path d="M1,1 C3,9 7,1 9,9" stroke="black" stroke-width="0.8" fill="none"/>'
            '</g></defs>')
    uses = "".join(f'<use xlink:href="#tile" x="{10 * (i % 11)}" y="{10 * (i // 11)}"/>'
                   for i in range(107))
    t = time.perf_counter()
    p = load_pattern(_svg(tmp_path, tile + uses, size='width="110" height="100"'))
    assert time.perf_counter() - t < 8
    assert len(shapely.get_parts(p.to_shapely())) >= 107


def test_a_placement_that_enlarges_a_render_loads_it_at_a_finer_pixel(tmp_path):
    from insitu.marking.placement import Placement

    path = _svg(tmp_path, _GRADIENT)
    natural = load_pattern(path)
    placed = Placement(str(path), (0.0, 0.0), 100.0).placed()
    scale = 100.0 / natural.mark_width
    assert natural.raster_mm == pytest.approx(0.05) and scale > 4
    assert placed.raster_mm * scale <= 0.05 * 1.01


def test_pattern_show_takes_paint_and_refuses_a_bad_one(tmp_path):
    from typer.testing import CliRunner

    from insitu.cli.main import app

    path = str(_svg(tmp_path, _GRADIENT))
    res = CliRunner().invoke(app, ["pattern", "show", path, "--paint", "dither"])
    assert res.exit_code == 0 and "0 contours" in res.output, res.output
    res = CliRunner().invoke(app, ["pattern", "show", path, "--paint", "blur"])
    assert res.exit_code == 1 and "--paint 'blur': expected one of threshold, dither" in res.output


def test_insitu_pattern_imports_only_what_patterns_need():
    import subprocess
    import sys

    code = ("import sys; sys.argv = ['insitu', 'pattern', '--help']\n"
            "from insitu.cli.entry import main\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('scipy', 'open3d', 'cv2', 'insitu.services', 'insitu.sim',"
            " 'matplotlib') if m in sys.modules]\n"
            "print('HEAVY', heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120).stdout
    assert "HEAVY []" in out, out


def test_conditional_attributes_apply_to_any_element(tmp_path):
    body = ('<rect width="10" height="10" systemLanguage="fr"/>'
            '<rect x="20" width="10" height="10" requiredExtensions="http://example.org/x"/>'
            '<rect x="40" width="10" height="10" systemLanguage="en-GB, fr"/>'
            '<rect x="60" width="10" height="10" requiredFeatures="NO_SUCH_FEATURE"/>'
            '<rect x="80" width="10" height="10" requiredFeatures='
            '"http://www.w3.org/TR/SVG11/feature#Shape"/>')
    assert _area(load_pattern(_svg(tmp_path, body))) == pytest.approx(200)


def test_a_link_inside_text_is_part_of_it_and_what_is_not_drawn_is_named(tmp_path):
    body = ('<text x="5 60" y="30" font-size="20"> <a href="#x"><tspan>AB</tspan></a></text>'
            '<text x="5" y="60" font-size="20" text-decoration="underline">C</text>'
            '<text x="5" y="90" font-size="20">\u0645\u0631\u062d\u0628\u0627</text>')
    p = load_pattern(_svg(tmp_path, body))
    assert not any("<a>" in n for n in p.notes)
    a_b = [g for g in shapely.get_parts(p.to_shapely()) if g.bounds[1] > 60 * PX]
    assert shapely.unary_union(a_b).bounds[0] / PX == pytest.approx(5, abs=2)  # the text's x
    assert shapely.unary_union(a_b).bounds[2] / PX > 60           # B at the second x
    assert any("text-decoration underline: not drawn" in n for n in p.notes)
    assert any("text in a script that needs shaping" in n for n in p.notes)


def test_a_drawing_of_light_paints_only_is_refused_saying_so(tmp_path):
    path = _svg(tmp_path, '<rect width="50" height="50" fill="#fad56e"/>')
    with pytest.raises(Exception, match="nothing it paints is dark enough to mark"):
        load_pattern(path)
    assert load_pattern(f"{path};paint=dither").paths               # its shade as dots


def test_light_paints_over_dark_ones_are_erased_quickly(tmp_path):
    body = '<rect width="200" height="200"/>' + "".join(
        f'<circle cx="{5 + 10 * (i % 20)}" cy="{5 + 10 * (i // 20)}" r="4" '
        f'fill="{"white" if i % 2 else "black"}"/><rect x="{10 * (i % 20)}" '
        f'y="{10 * (i // 20)}" width="2" height="2"/>' for i in range(400))
    t = time.process_time()
    p = load_pattern(_svg(tmp_path, body, size='width="200" height="200"'))
    assert time.process_time() - t < 4                 # CPU: one cut per dark piece
    assert _area(p) == pytest.approx(40000 - 200 * 3.14159 * 16, rel=1e-3)   # white erases
