"""``insitu depth`` on a crossed scan (no renderer): the lines grouped into their two passes by
direction, each pocket measured from each pass on its own and the depths combined by their
inverse variances; a pocket one pass cannot measure measured from the other, said; a pass too
small, or lines in more than two directions, refused in one line; ``--pass`` choosing."""

import json

import numpy as np
import pytest
import shapely
import shapely.affinity
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.errors import ConfigError, MeasurementError
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.marking.engrave_passes import combine, line_passes, obliquity
from insitu.marking.engrave_stats import SHARED_MM
from insitu.services.depth import DepthScan, finding_points, measure_pockets
from insitu.services.depth_find import find_pockets

POCKET = shapely.box(-1, -1, 1, 1)
DEPTH = 0.2


def _crossed(angles=(0.0, 45.0), spacings=(0.1, 0.1), noises=(0.003, 0.003),
             lines=(None, None), seed=0, floor_errors=(0.0, 0.0)):
    """Passes of lines turned ``angles`` (°) from along y, ``spacings`` mm apart, with
    ``noises`` mm of height noise, each pass at most ``lines`` lines (None: all), over a top at
    5 mm with a 2 × 2 mm pocket :data:`DEPTH` deep at the origin, in x, y within ±3 mm, each
    line's floor points off by an error of ``floor_errors`` mm rms (the floor's speckle it
    crosses); each pass's line ids from 1000 × its place: (points (N, 3), line (N,))."""
    rng = np.random.default_rng(seed)
    pts, line = [], []
    for p, (angle, spacing, noise, most, shared) in enumerate(
            zip(angles, spacings, noises, lines, floor_errors + (0.0,) * len(angles))):
        a = np.radians(angle)
        along, across = np.array([-np.sin(a), np.cos(a)]), np.array([np.cos(a), np.sin(a)])
        t = np.arange(-5.0, 5.0, 0.04)
        offsets = np.arange(-5.0, 5.0, spacing)
        for k, c in enumerate(offsets):
            xy = c * across + t[:, None] * along
            xy = xy[np.all(np.abs(xy) <= 3.0, axis=1)]
            if len(xy) == 0:
                continue
            if most is not None and abs(c) > most * spacing / 2:
                continue
            inside = np.all(np.abs(xy) < 1, axis=1)
            z = (5.0 - np.where(inside, DEPTH + shared * rng.standard_normal(), 0.0)
                 + noise * rng.standard_normal(len(xy)))
            pts.append(np.column_stack([xy, z]))
            line.append(np.full(len(xy), 1000 * p + k))
    return np.vstack(pts), np.concatenate(line)


def test_the_lines_fall_into_their_passes_the_first_recorded_numbered_1():
    """Lines along y and at 45° (the short ones in the region's corners too, by their ids):
    two passes, along y first unless the first recorded direction says otherwise."""
    pts, line = _crossed()
    one, two = line_passes(pts[:, :2], line)
    assert (one.number, two.number) == (1, 2)
    assert one.angle_deg == pytest.approx(90.0, abs=0.1)
    assert two.angle_deg == pytest.approx(135.0, abs=0.1)
    assert np.all(one.lines < 1000) and np.all(two.lines >= 1000)
    assert len(one.lines) + len(two.lines) == len(np.unique(line))
    first, second = line_passes(pts[:, :2], line, first=np.array([-1.0, 1.0]))
    assert first.angle_deg == pytest.approx(135.0, abs=0.1) and second.number == 2
    pts, line = _crossed(angles=(20.0,), spacings=(0.1,), noises=(0.003,), lines=(None,))
    (only,) = line_passes(pts[:, :2], line)
    assert only.angle_deg == pytest.approx(110.0, abs=0.1)


def test_lines_in_more_than_two_directions_or_a_fan_of_them_are_refused():
    """Three directions; a fan of lines 0 … 20° from along y, 4° apart. Two sets only 5°
    apart are one pass (parallel enough: measured as one)."""
    pts, line = _crossed(angles=(0.0, 45.0, -30.0), spacings=(0.1,) * 3, noises=(0.003,) * 3,
                         lines=(None,) * 3)
    with pytest.raises(MeasurementError, match=r"more than two directions \(90°, 135°, 60°"):
        line_passes(pts[:, :2], line)
    fan = tuple(np.arange(0.0, 21.0, 4.0))
    pts, line = _crossed(angles=fan, spacings=(0.3,) * 6, noises=(0.003,) * 6,
                         lines=(None,) * 6)
    with pytest.raises(MeasurementError, match="more than two directions"):
        line_passes(pts[:, :2], line)
    pts, line = _crossed(angles=(0.0, 5.0))
    (one,) = line_passes(pts[:, :2], line)
    assert len(one.lines) == len(np.unique(line))
    (p,) = measure_pockets(DepthScan(pts, line, None, "plane"), [POCKET], 0.005)
    assert p.passes == () and abs(p.mean_mm - DEPTH) < 3 * p.sem_mm


def test_combine_weights_the_passes_by_their_inverse_variances():
    """Independent errors: weights 100 and 25; an error of 0.06 common to both passes: the
    rest (0.08 each) halves in variance, the common part stays."""
    mean, sem = combine([(1.0, 0.1), (2.0, 0.2)])
    assert mean == pytest.approx((1.0 * 100 + 2.0 * 25) / 125)
    assert sem == pytest.approx(1 / np.sqrt(125))
    mean, sem = combine([(1.0, 0.1), (2.0, 0.1)], shared_mm=0.06)
    assert mean == pytest.approx(1.5) and sem == pytest.approx(np.sqrt(0.0064 / 2 + 0.0036))
    assert combine([(1.0, 0.1)], shared_mm=0.06) == pytest.approx((1.0, 0.1))


def test_a_crossed_scan_measures_each_pass_and_combines_them():
    """Lines along y and along x, both square to the walls; pass 2's lines four times as far
    off on the floor: each pass's depth within 3σ of the truth, the combined one their
    inverse-variance mean (SHARED_MM common to both), within 3 µm of the truth and surer
    than either."""
    pts, line = _crossed(angles=(0.0, 90.0), floor_errors=(0.003, 0.012), seed=1)
    (p,) = measure_pockets(DepthScan(pts, line, None, "plane"), [POCKET], 0.005)
    assert p.refused is None and p.note is None and len(p.passes) == 2
    one, two = p.passes
    assert one.line_pass.number == 1 and two.line_pass.number == 2
    for q in (one, two):
        assert q.map is not None and q.map.floor_lines >= 8
        assert abs(q.mean_mm - DEPTH) < 3 * q.sem_mm, q
    assert two.sem_mm > 1.5 * one.sem_mm
    expect = combine([(one.mean_mm, one.sem_mm), (two.mean_mm, two.sem_mm)], SHARED_MM)
    assert (p.mean_mm, p.sem_mm) == pytest.approx(expect)
    assert p.sem_mm < one.sem_mm and abs(p.mean_mm - DEPTH) < 0.003 and p.stated
    assert p.floor_lines == one.map.floor_lines + two.map.floor_lines


def test_a_pocket_one_pass_cannot_measure_is_measured_from_the_other_and_says_so():
    """The crossed pass's 20 lines only 1 mm either side of the pocket's centre: the pocket
    reaches beyond its points; pass 1 alone measures, and says so."""
    pts, line = _crossed(lines=(None, 20))
    (p,) = measure_pockets(DepthScan(pts, line, None, "plane"), [POCKET], 0.005)
    one, two = p.passes
    assert two.map is None and "reaches beyond the scan's points" in two.refused
    assert (p.mean_mm, p.sem_mm) == (one.mean_mm, one.sem_mm) and p.stated
    assert p.note.startswith("measured from pass 1 (lines at 90° to x) alone")
    assert "pass 2 (lines at 135° to x) not: it reaches beyond" in p.note


def test_a_pass_with_few_lines_on_the_floor_counts_but_the_depth_is_not_stated():
    """The crossed pass (along x) 0.35 mm apart: 2–7 lines on the floor; its depth counts
    with its σ, the combined depth is not stated, and the note names that pass and the
    spacing."""
    pts, line = _crossed(angles=(0.0, 90.0), spacings=(0.1, 0.35))
    (p,) = measure_pockets(DepthScan(pts, line, None, "plane"), [POCKET], 0.005)
    one, two = p.passes
    assert two.map is not None and 2 <= two.map.floor_lines < 8 and one.note is None
    assert "depth not stated" in two.note
    assert (p.mean_mm, p.sem_mm) == pytest.approx(combine(
        [(one.mean_mm, one.sem_mm), (two.mean_mm, two.sem_mm)], SHARED_MM))
    assert 2 * p.sem_mm <= 0.005 and not p.stated
    assert p.note.startswith("pass 2 (lines at 0° to x): depth not stated") and "≤ " in p.note


def test_a_pass_slanted_to_the_walls_is_shown_not_combined():
    """Lines along y and at 45° over a square pocket: the 45° pass is measured and reported,
    but the depth is pass 1's alone, and the note says why and how to use pass 2; how far a
    pass is from square to a pocket's walls, turned or not."""
    pts, line = _crossed(seed=3)
    (p,) = measure_pockets(DepthScan(pts, line, None, "plane"), [POCKET], 0.005)
    one, two = p.passes
    assert one.map is not None and two.map is not None
    assert (p.mean_mm, p.sem_mm) == pytest.approx(combine([(one.mean_mm, one.sem_mm)],
                                                          SHARED_MM)) and p.stated
    assert p.note.startswith("pass 2 (lines at 135° to x) not combined")
    assert "45° from square (pass 1 (lines at 90° to x): 0°)" in p.note
    assert "--pass 2 uses it alone" in p.note
    assert one.combined and not two.combined and p.floor_lines == one.map.floor_lines
    assert obliquity(90.0, POCKET) == pytest.approx(0.0)
    assert obliquity(100.0, POCKET) == pytest.approx(10.0)
    assert obliquity(135.0, POCKET) == pytest.approx(45.0)
    assert obliquity(135.0, shapely.affinity.rotate(POCKET, 45.0)) == pytest.approx(0.0)


def test_a_pass_too_small_is_refused_unless_the_other_is_asked_for():
    pts, line = _crossed(lines=(None, 4))
    scan = DepthScan(pts, line, None, "plane")
    with pytest.raises(MeasurementError, match=r"pass 2 \(lines at 135° to x\) holds 4 lines"
                                               r".*--pass 1"):
        measure_pockets(scan, [POCKET], 0.005)
    (p,) = measure_pockets(scan, [POCKET], 0.005, which="1")
    assert [q.line_pass.number for q in p.passes] == [1] and abs(p.mean_mm - DEPTH) < 0.003
    with pytest.raises(ConfigError, match="no crossed one"):
        measure_pockets(DepthScan(*_crossed(angles=(0.0,), spacings=(0.1,), noises=(0.003,),
                                            lines=(None,)), None, "plane"),
                        [POCKET], 0.005, which="2")


def test_a_crossed_scans_pockets_are_found_on_its_first_pass():
    """On the first pass asked for (pass 1, or 2 with --pass 2): the outline within two raster
    cells (0.1 mm) of the pocket's walls, and the pocket measured from it as from its true
    outline, by both passes."""
    pts, line = _crossed()
    scan = DepthScan(pts, line, None, "plane")
    on, on_line = finding_points(scan)
    assert np.all(on_line < 1000) and len(on_line) == (line < 1000).sum()
    assert np.all(finding_points(scan, "2")[1] >= 1000)
    (found,) = find_pockets(on, on_line)
    assert found.hausdorff_distance(POCKET) < 0.1, found
    mine, given = measure_pockets(scan, [found, POCKET], 0.005)
    assert len(mine.passes) == 2 and abs(mine.mean_mm - DEPTH) < 3 * mine.sem_mm
    assert abs(mine.mean_mm - given.mean_mm) < 2 * mine.sem_mm


def test_the_pass_option_chooses_and_the_report_gives_each_pass(tmp_path):
    pts, line = _crossed(angles=(0.0, 90.0), floor_errors=(0.004, 0.006), seed=2)
    write_ply(tmp_path / "crossed.ply", PointCloud(pts, {"line": line.astype(np.int32)}))
    got = {}
    for which in ("both", "1", "2"):
        out = tmp_path / f"report-{which}"
        run = CliRunner().invoke(app, ["depth", str(tmp_path / "crossed.ply"), "--pocket",
                                       "-1,-1,1,1", "--pass", which, "-o", str(out)])
        assert run.exit_code == 0, run.output
        (got[which],) = json.loads((out / "depth.json").read_text())["pockets"]
        assert (out / got[which]["picture"]).is_file()
    both = got["both"]
    assert [q["pass"] for q in both["passes"]] == [1, 2]
    assert [q["pass"] for q in got["1"]["passes"]] == [1]
    assert [q["pass"] for q in got["2"]["passes"]] == [2]
    for k, which in enumerate(("1", "2")):
        assert got[which]["depth_mm"] == both["passes"][k]["depth_mm"]
        assert got[which]["sigma_mm"] == both["passes"][k]["sigma_mm"]
    assert both["sigma_mm"] < min(q["sigma_mm"] for q in both["passes"])
    assert abs(both["depth_mm"] - DEPTH) < 0.003
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "crossed.ply"), "--pocket",
                                   "-1,-1,1,1", "--pass", "3"])
    assert run.exit_code == 2 and "--pass" in run.output
    pts, line = _crossed(lines=(None, 4))
    write_ply(tmp_path / "small.ply", PointCloud(pts, {"line": line.astype(np.int32)}))
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "small.ply"), "--pocket",
                                   "-1,-1,1,1"])
    assert run.exit_code == 1 and "small.ply: pass 2" in run.output and "holds 4" in run.output
