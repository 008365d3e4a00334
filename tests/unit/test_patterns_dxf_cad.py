"""DXF files marked as a CAD program shows them: units only from a $INSUNITS the file holds,
hidden layers left out (also through blocks), linetypes as dashes, pattern hatches as their
lines, pictures and malformed entities named, a file of meshes refused saying so."""

from __future__ import annotations

import ezdxf
import numpy as np
import pytest
import shapely

from insitu.errors import FormatError
from insitu.patterns import load_pattern

_NO_HEADER = ("0\nSECTION\n2\nENTITIES\n0\nLINE\n8\n0\n10\n0\n20\n0\n11\n40\n21\n10\n"
              "0\nENDSEC\n0\nEOF\n")


def _length(paths) -> float:
    return sum(shapely.LineString(p).length for p in paths if len(p) >= 2)


def test_a_dxf_without_a_header_is_not_read_in_metres(tmp_path):
    path = tmp_path / "noheader.dxf"          # ezdxf fills in a header with $INSUNITS 6 (m)
    path.write_text(_NO_HEADER)
    p = load_pattern(path)
    assert p.notes[0].startswith("units: none in the file")
    assert p.size == pytest.approx((40.0, 10.0))
    assert load_pattern(f"{path};units=m").size == pytest.approx((40000.0, 10000.0))


def test_a_header_with_insunits_is_read(tmp_path):
    doc = ezdxf.new(units=5)                   # cm
    doc.modelspace().add_line((0, 0), (4, 1))
    doc.saveas(tmp_path / "cm.dxf")
    p = load_pattern(tmp_path / "cm.dxf")
    assert "$INSUNITS 5" in p.notes[0] and p.size == pytest.approx((40.0, 10.0))


@pytest.mark.parametrize("hide", ["off", "frozen", "plot"])
def test_layers_that_are_off_frozen_or_not_plotted_are_not_marked(tmp_path, hide):
    doc = ezdxf.new(units=4)
    layer = doc.layers.add("NOTES")
    if hide == "off":
        layer.off()
    elif hide == "frozen":
        layer.freeze()
    else:
        layer.dxf.plot = 0
    msp = doc.modelspace()
    msp.add_line((0, 0), (10, 0))
    msp.add_line((0, 0), (500, 300), dxfattribs={"layer": "NOTES"})
    block = doc.blocks.new("TAG")
    block.add_circle((0, 0), 50)                             # on layer 0: the insert's layer
    msp.add_blockref("TAG", (200, 200), dxfattribs={"layer": "NOTES"})
    doc.saveas(tmp_path / "hidden.dxf")
    p = load_pattern(tmp_path / "hidden.dxf")
    assert p.size == pytest.approx((10.0, 0.0), abs=1e-9)
    assert any("2 entities on layers that are off, frozen or not plotted" in n for n in p.notes)


def test_a_block_on_a_visible_layer_keeps_its_own_hidden_layers(tmp_path):
    doc = ezdxf.new(units=4)
    doc.layers.add("HIDDEN").off()
    block = doc.blocks.new("B")
    block.add_line((0, 0), (10, 0))
    block.add_line((0, 0), (0, 99), dxfattribs={"layer": "HIDDEN"})
    doc.modelspace().add_blockref("B", (0, 0))
    doc.saveas(tmp_path / "b.dxf")
    assert load_pattern(tmp_path / "b.dxf").size == pytest.approx((10.0, 0.0), abs=1e-9)


def test_a_dashed_linetype_is_marked_as_its_dashes(tmp_path):
    doc = ezdxf.new(setup=True, units=4)     # DASHED: 1.27 on, 0.254 off (× $LTSCALE 1)
    doc.layers.add("AXES", linetype="DASHED")
    doc.modelspace().add_line((0, 0), (190.5, 0), dxfattribs={"layer": "AXES"})
    doc.modelspace().add_line((0, 10), (190.5, 10))
    doc.saveas(tmp_path / "dashes.dxf")
    p = load_pattern(tmp_path / "dashes.dxf")
    flat = [q for q in p.paths if np.allclose(q[:, 1], 0)]
    assert len(flat) == 125 and _length(flat) == pytest.approx(125 * 1.27, rel=1e-9)
    assert _length([q for q in p.paths if np.allclose(q[:, 1], 10)]) == pytest.approx(190.5)


def test_a_pattern_hatch_is_its_pattern_lines_and_a_solid_one_an_area(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    h = msp.add_hatch()
    h.set_pattern_fill("ANSI31", scale=1.0)             # 45° lines 3.175 apart
    h.paths.add_polyline_path([(0, 0), (50, 0), (50, 50), (0, 50)], is_closed=True)
    s = msp.add_hatch()
    s.paths.add_polyline_path([(100, 0), (110, 0), (110, 10), (100, 10)], is_closed=True)
    doc.saveas(tmp_path / "hatch.dxf")
    p = load_pattern(tmp_path / "hatch.dxf")
    assert p.to_shapely().area == pytest.approx(100.0)                 # only the solid one
    lines = [q for q in p.paths if q[:, 0].max() <= 50 + 1e-6]
    assert len(lines) > 15
    d = np.diff(np.concatenate([q[[0, -1]] for q in lines]).reshape(-1, 2, 2), axis=1)[:, 0]
    assert np.allclose(np.abs(d[:, 0]), np.abs(d[:, 1]), atol=1e-6)    # all at ±45°
    assert any("1 pattern hatch(es) marked as their pattern lines" in n for n in p.notes)


def test_an_image_is_named_in_a_warning(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    msp.add_line((0, 0), (10, 0))
    img = doc.add_image_def(filename="photo.png", size_in_pixel=(100, 100))
    msp.add_image(img, insert=(0, 0), size_in_units=(10, 10))
    doc.saveas(tmp_path / "img.dxf")
    p = load_pattern(tmp_path / "img.dxf")
    assert "warning: 1 IMAGE (raster picture) not marked" in p.notes


def test_a_malformed_entity_is_skipped_and_named(tmp_path):
    doc = ezdxf.new(units=4)
    msp = doc.modelspace()
    msp.add_line((0, 0), (10, 0))
    c = msp.add_circle((5, 5), 1)
    c.dxf.radius = 0.0
    doc.saveas(tmp_path / "bad.dxf")
    p = load_pattern(tmp_path / "bad.dxf")
    warning = [n for n in p.notes if n.startswith("warning: 1 malformed entity skipped")]
    assert len(warning) == 1 and f"CIRCLE #{c.dxf.handle} has radius 0" in warning[0]
    assert p.size == pytest.approx((10.0, 0.0), abs=1e-9)


def test_a_file_of_meshes_only_is_refused_saying_so(tmp_path):
    doc = ezdxf.new(units=4)
    mesh = doc.modelspace().add_mesh()
    with mesh.edit_data() as m:
        m.vertices = [(0, 0, 0), (1, 0, 0), (1, 1, 1)]
        m.faces = [(0, 1, 2)]
    doc.saveas(tmp_path / "mesh.dxf")
    with pytest.raises(FormatError, match=r"mesh\.dxf: holds only 3-D geometry \(MESH ×1\)"):
        load_pattern(tmp_path / "mesh.dxf")
