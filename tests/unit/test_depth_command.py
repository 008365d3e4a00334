"""``insitu depth`` on measured clouds (no renderer): each pocket's depth from the floor and top
of the same lines, and one line for each pocket it cannot measure — outside the scan, beyond
its points, too few lines on its floor (with the spacing that gives enough), no top around
it — while the others are still measured; exit 1 when none is; the report
folder written whole or not at all."""

import json

import numpy as np
import pytest
import shapely
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.errors import ConfigError, FormatError
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.services import depth_report
from insitu.services.depth import DepthScan, load_depth_scan, measure_pockets

POCKET = "-1,-1,1,1"


def _cloud(spacing=0.1, angle_deg=0.0, x=(-3.0, 3.0), y=(-3.0, 3.0), depth=0.2, seed=0,
           cross=False):
    """Lines ``spacing`` mm apart, turned ``angle_deg`` from along y, over a top at 5 mm with
    a 2 × 2 mm pocket ``depth`` deep at the origin, 3 µm noise; with ``cross`` a second pass
    at 45°: (points (N, 3), line (N,))."""
    rng = np.random.default_rng(seed)
    pts, line = [], []
    for angle in (angle_deg, 45.0) if cross else (angle_deg,):
        a = np.radians(angle)
        along, across = np.array([-np.sin(a), np.cos(a)]), np.array([np.cos(a), np.sin(a)])
        t = np.arange(-5.0, 5.0, 0.04)
        for k, c in enumerate(np.arange(-5.0, 5.0, spacing)):
            xy = c * across + t[:, None] * along
            keep = ((xy[:, 0] >= x[0]) & (xy[:, 0] <= x[1]) & (xy[:, 1] >= y[0])
                    & (xy[:, 1] <= y[1]))
            xy = xy[keep]
            inside = (np.abs(xy[:, 0]) < 1) & (np.abs(xy[:, 1]) < 1)
            z = 5.0 - np.where(inside, depth, 0.0) + 0.003 * rng.standard_normal(len(xy))
            pts.append(np.column_stack([xy, z]))
            line.append(np.full(len(xy), k + 1000 * (angle != angle_deg)))
    return np.vstack(pts), np.concatenate(line)


def _scan(**kw) -> DepthScan:
    return DepthScan(*_cloud(**kw), None, "plane")


def test_a_pocket_is_measured_from_its_floor_and_the_top_of_the_same_lines():
    (p,) = measure_pockets(_scan(), [shapely.box(-1, -1, 1, 1)], 0.005)
    assert p.refused is None and abs(p.mean_mm - 0.2) < 3 * p.sem_mm and p.stated
    assert p.map.floor_lines >= 8


def test_each_pocket_it_cannot_measure_says_why_and_what_to_do():
    """Outside the scan; reaching beyond its points; 1.2 mm lines (one on the floor);
    lines only over the pocket (no top); a box between two lines. Each one
    line, the pocket beside it still measured."""
    good = shapely.box(-1, -1, 1, 1)
    cases = [
        (_scan(), shapely.box(8, -1, 10, 1), "lies outside the scan"),
        (_scan(), shapely.box(2, -1, 4, 1), "reaches beyond the scan's points"),
        (_scan(spacing=1.2), good, "1 scan line crosses its floor"),
        (_scan(x=(-1.15, 1.15), y=(-1.15, 1.15)), good, "on the top around the pocket"),
        (_scan(spacing=1.5), shapely.box(0.1, -1, 0.4, 1), "lie on its floor"),
    ]
    for scan, region, why in cases:
        results = measure_pockets(scan, [region, good], 0.005)
        assert results[0].map is None and why in results[0].refused, results[0].refused
    assert measure_pockets(_scan(), [shapely.box(8, -1, 10, 1), good], 0.005)[1].map is not None


def test_a_floor_of_few_lines_is_measured_not_stated_and_names_the_spacing_that_would():
    """0.3 mm lines put 5 on the floor, fewer than the 8 a statement needs: the depth and
    its σ come out, not stated, with the spacing that
    gives 8 (≤ 0.19 mm), which does."""
    (p,) = measure_pockets(_scan(spacing=0.3), [shapely.box(-1, -1, 1, 1)], 0.005)
    assert p.refused is None and not p.stated and 2 <= p.map.floor_lines < 8
    assert abs(p.mean_mm - 0.2) < 3 * p.sem_mm and "depth not stated" in p.note
    asked = float(p.note.split("≤ ")[1].split(" mm")[0])
    assert asked == pytest.approx(0.19, abs=0.011)
    (q,) = measure_pockets(_scan(spacing=asked), [shapely.box(-1, -1, 1, 1)], 0.005)
    assert q.map is not None and q.map.floor_lines >= 8 and q.note is None


def test_a_cloud_needs_its_lines_and_takes_no_height_calibration(tmp_path):
    pts, line = _cloud()
    write_ply(tmp_path / "no-lines.ply", PointCloud(pts))
    with pytest.raises(FormatError, match="no line index"):
        load_depth_scan(tmp_path / "no-lines.ply")
    write_ply(tmp_path / "cloud.ply", PointCloud(pts, {"line": line.astype(np.int32)}))
    with pytest.raises(ConfigError, match="--height-cal is for a recorded scan"):
        load_depth_scan(tmp_path / "cloud.ply", height_cal=object())
    with pytest.raises(ConfigError, match="expected a recorded scan folder"):
        load_depth_scan(tmp_path / "cloud.csv")


def test_the_command_tables_each_pocket_and_exits_1_when_none_is_measured(tmp_path):
    pts, line = _cloud()
    write_ply(tmp_path / "cloud.ply", PointCloud(pts, {"line": line.astype(np.int32)}))
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "cloud.ply"), "--pocket", POCKET,
                                   "--pocket", "8,-1,10,1", "-o", str(tmp_path / "report")])
    assert run.exit_code == 0, run.output
    assert "0.20" in run.output and "pocket 8 -1 10 1: not measured" in run.output
    report = json.loads((tmp_path / "report" / "depth.json").read_text())
    first, second = report["pockets"]
    assert abs(first["depth_mm"] - 0.2) < 3 * first["sigma_mm"] and first["stated"]
    assert (tmp_path / "report" / first["picture"]).is_file()
    assert "outside the scan" in second["refused"] and "picture" not in second
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "cloud.ply"), "--pocket",
                                   "8,-1,10,1"])
    assert run.exit_code == 1 and "no pocket measured" in run.output
    corners = "-1,-1,1,-1,1,1,-1,1"       # the same pocket as its outline's corners
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "cloud.ply"), "--pocket", corners,
                                   "-o", str(tmp_path / "corners")])
    again = json.loads((tmp_path / "corners" / "depth.json").read_text())["pockets"][0]
    assert run.exit_code == 0 and again["depth_mm"] == first["depth_mm"]
    for bad in ("1,1,-1,-1", "1,2,3", "0,0,1,1,0,1,1,0"):
        run = CliRunner().invoke(app, ["depth", str(tmp_path / "cloud.ply"), "--pocket", bad])
        assert run.exit_code == 1 and f"--pocket {bad!r}" in run.output


def test_a_failed_report_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    pts, line = _cloud()
    write_ply(tmp_path / "cloud.ply", PointCloud(pts, {"line": line.astype(np.int32)}))
    report = tmp_path / "report"
    report.mkdir()
    (report / "depth.json").write_text("old")

    def broken(path, *a, **kw):
        path.write_bytes(b"half")
        raise FormatError(f"{path}: disk full")
    monkeypatch.setattr(depth_report, "depth_picture", broken)
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "cloud.ply"), "--pocket", POCKET,
                                   "-o", str(report)])
    assert run.exit_code != 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cloud.ply", "report"]
    assert [p.name for p in report.iterdir()] == ["depth.json"]
    assert (report / "depth.json").read_text() == "old"


def test_without_a_height_calibration_the_pockets_far_out_in_the_field_are_named():
    from insitu.services.depth import plane_scale_warning

    near, far = shapely.box(-1, -1, 1, 1), shapely.box(40, -1, 42, 1)
    assert "beyond" not in plane_scale_warning([near])
    text = plane_scale_warning([near, far])
    assert "40 -1 42 1" in text and "-1 -1 1 1" not in text and "--height-cal" in text


def test_many_points_inside_a_pocket_that_cannot_be_floor_are_said():
    """Two lines inside the pocket read 3 mm above the top (another light path taken for the
    line): the depth is the floor's, and the pocket's result says how many points were left
    out; a clean scan says nothing."""
    pts, line = _cloud()
    ghost = (np.abs(pts[:, 0] + 0.8) < 0.06) & (np.abs(pts[:, 1]) < 0.9)
    pts[ghost, 2] += 3.0
    (p,) = measure_pockets(DepthScan(pts, line, None, "plane"), [shapely.box(-1, -1, 1, 1)],
                           0.005)
    assert abs(p.mean_mm - 0.2) < 3 * p.sem_mm
    assert p.map.not_floor >= ghost.sum() - 2 and str(p.map.not_floor) in p.off_floor
    (clean,) = measure_pockets(_scan(), [shapely.box(-1, -1, 1, 1)], 0.005)
    assert clean.off_floor is None
