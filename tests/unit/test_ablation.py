"""The simulator's material removal (sim/ablation.py) against the logarithmic ablation law, per
material, and the materials table's nominal depth per pass (formats/materials.py) against it."""

import math

import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats.materials import DEFAULT_MATERIALS, LaserSource, Material, read_materials
from insitu.formats.pens import Pen
from insitu.sim.ablation import (
    ABLATION,
    CELL_MM,
    Engraving,
    MarkingBeam,
    ablate,
    engraved_part,
)
from insitu.sim.workpieces import make_workpiece

BEAM = MarkingBeam()
FREQ_KHZ, SPEED, HATCH = 40.0, 800.0, 0.02


def _hatch(eng, part, power_pct, focus_dz=0.0, size=1.0, seed=1):
    """One pass of a hatch over a ``size`` mm square at the part's centre (y lines, HATCH
    apart, samples 0.005 mm apart carrying the pulses fired over them)."""
    rng = np.random.default_rng(seed)
    step = 0.005
    xs = np.arange(-size / 2, size / 2 + 1e-9, step)
    top = float(part.height(np.array([0.0]), np.array([0.0]))[0])
    for y in np.arange(-size / 2, size / 2 + 1e-9, HATCH):
        uv = np.column_stack([xs, np.full_like(xs, y)])
        eng.cover(part, uv.min(0), uv.max(0))
        pulses = np.full(len(xs), FREQ_KHZ * 1e3 * step / SPEED)
        ablate(eng, BEAM, uv, np.full(len(xs), top + focus_dz), pulses, power_pct, FREQ_KHZ,
               rng)


def _law_depth(m, power_pct, waist_mm=BEAM.waist_mm):
    """The law's depth per pass on a flat floor in focus: V per pulse × pulses per area."""
    energy = BEAM.power_w * power_pct / 100 / (FREQ_KHZ * 1e3)
    w_cm = waist_mm / 10
    log_f = math.log(2 * energy / (math.pi * w_cm ** 2) / m.threshold_j_cm2)
    volume = math.pi * waist_mm ** 2 * m.penetration_um * 1e-3 * log_f ** 2 / 4
    return volume * FREQ_KHZ * 1e3 / (SPEED * HATCH)


def _centre(eng, half=0.3):
    """Mean removed depth and mean rate factor over the hatch's centre (±half mm)."""
    xs, ys = eng.nodes()
    sel = (np.abs(ys)[:, None] <= half) & (np.abs(xs)[None, :] <= half)
    return float(eng.removed[sel].mean()), float(eng.rate[sel].mean())


# powers that remove some 5 … 10 µm a pass: the floor stays flat within a pass (deeper
# passes leave each line's trench sloped under the next line, which then removes less)
POWER = {"blank-stainless": 30.0, "blank-anodised": 30.0, "blank-beech": 6.0}


@pytest.mark.parametrize("name", sorted(ABLATION))
def test_one_pass_removes_what_the_ablation_law_says(name):
    part = make_workpiece(name)
    m, power = ABLATION[name], POWER[name]
    eng = Engraving(m, seed=3)
    _hatch(eng, part, power)
    depth, rate = _centre(eng)
    # the blank's own rate (its spread and grain) is the truth the loop has to learn
    assert depth / rate == pytest.approx(_law_depth(m, power), rel=0.04)
    assert 1 - m.rate_spread - 2 * m.grain <= rate <= 1 + m.rate_spread + 2 * m.grain
    # less energy removes by ln² of the fluence: 60 % of the energy, some 40 % of the depth
    eng2 = Engraving(m, seed=3)
    _hatch(eng2, part, 0.6 * power)
    assert _centre(eng2)[0] / rate == pytest.approx(_law_depth(m, 0.6 * power), rel=0.05)


def test_below_the_threshold_nothing_is_removed_and_defocus_removes_less():
    part = make_workpiece("blank-stainless")
    m = ABLATION["blank-stainless"]
    # F0 = 2E / (π w²) below F_th: the pulse energy of 1 % of the power
    eng = Engraving(m, seed=3)
    _hatch(eng, part, 0.5)
    assert not np.any(eng.removed > 0)
    focused, defocused = Engraving(m, seed=3), Engraving(m, seed=3)
    _hatch(focused, part, 30.0)
    _hatch(defocused, part, 30.0, focus_dz=2.0)
    assert _centre(defocused)[0] < 0.6 * _centre(focused)[0]


def test_a_floor_deepens_pass_after_pass_and_its_walls_are_tapered():
    part = make_workpiece("blank-anodised")
    eng = Engraving(ABLATION["blank-anodised"], seed=4)
    for k in range(6):
        _hatch(eng, part, 30.0, seed=k)
    xs, ys = eng.nodes()
    row = eng.removed[np.argmin(np.abs(ys)), :]
    depth = float(row[np.abs(xs) <= 0.3].mean())
    assert depth > 5 * _law_depth(ABLATION["blank-anodised"], 30.0) * 0.8
    # the wall: from 10 % to 90 % of the depth over more than one cell (not a vertical step)
    edge = xs[(xs > 0.3) & (xs < 0.8)]
    prof = row[(xs > 0.3) & (xs < 0.8)]
    x90, x10 = edge[np.argmax(prof < 0.9 * depth)], edge[np.argmax(prof < 0.1 * depth)]
    assert x10 - x90 > 2 * CELL_MM


def test_the_surface_the_camera_sees_is_the_floor_removed_not_one_phase_of_its_hatch():
    """Six passes of a hatch 0.02 mm apart leave ridges at the removal grid's finest period;
    the ray-cast mesh (every 2nd node) stands at the floor's mean depth, not at its ridges'
    or furrows' (sampled at one phase they differ from it by ~5 %)."""
    part = make_workpiece("blank-stainless")
    eng = Engraving(ABLATION["blank-stainless"], seed=2)
    for k in range(6):
        _hatch(eng, part, 80.0, seed=k)
    xs, ys = eng.nodes()
    inner = np.ix_(np.abs(ys) < 0.35, np.abs(xs) < 0.35)
    mean = float(eng.removed[inner].mean())
    phases = [float(eng.removed[inner][a::2, b::2].mean()) for a in (0, 1) for b in (0, 1)]
    assert max(abs(p - mean) for p in phases) > 0.02 * mean      # the ridges are there
    mesh = engraved_part(part, eng)
    v = mesh.vertices
    top = float(part.height(np.array([0.0]), np.array([0.0]))[0])
    on = (np.abs(v[:, 0]) < 0.35) & (np.abs(v[:, 1]) < 0.35) & (v[:, 2] > top - 1.0)
    assert on.sum() > 500
    assert top - float(v[on, 2].mean()) == pytest.approx(mean, rel=0.005)


def test_material_table_depth_per_pass_is_the_law_of_its_constants():
    m = ABLATION["blank-stainless"]
    pen = Pen(name="t", power_pct=80.0, frequency_khz=FREQ_KHZ, mark_speed_mm_s=SPEED)
    mat = Material(name="steel", threshold_j_cm2=m.threshold_j_cm2,
                   penetration_um=m.penetration_um, hatch_mm=HATCH, pen=pen)
    laser = LaserSource(power_w=BEAM.power_w, spot_um=2e3 * BEAM.waist_mm)
    assert mat.depth_per_pass_mm(laser) == pytest.approx(_law_depth(m, 80.0), rel=1e-9)
    assert mat.depth_per_pass_mm(laser, power_pct=0.5) == 0.0
    for built_in in DEFAULT_MATERIALS.materials:      # each pen of the table removes material
        assert 0.002 < built_in.depth_per_pass_mm(DEFAULT_MATERIALS.laser) < 0.02


def test_materials_file_names_the_field_and_the_material(tmp_path):
    f = tmp_path / "materials.json"
    f.write_text('{"format": "insitu-materials/1", "materials": [{"name": "steel", '
                 '"threshold_j_cm2": -1, "penetration_um": 0.4, "pen": {"name": "p"}}]}')
    with pytest.raises(FormatError, match=r"materials\.json.*threshold_j_cm2"):
        read_materials(f)
    with pytest.raises(FormatError, match=r"--material: no material 'glass'; the materials "
                                          r"are 'stainless-steel'"):
        DEFAULT_MATERIALS.material("glass", "--material")
