"""Pockets found on a scan (``insitu depth`` without ``--pocket``): regions below the top by
more than its noise, of at least 0.5 mm², a rectangle outlined on the walls (where the depth
crosses half the pocket's), so the floor set measure_depth takes is the one the true outline
gives; small dips and noise are not pockets."""

import json

import numpy as np
import shapely
import shapely.affinity
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.services.depth import DepthScan, measure_pockets
from insitu.services.depth_find import find_pockets

TAPER = 0.03


def _cloud(pockets, noise=0.005, seed=0, spacing=0.1):
    """Lines along y ``spacing`` mm apart over a tilted top at 5 mm with ``pockets``: (side
    u, side v, centre, turn °, depth mm) each, their walls tapered over 30 µm: (points, line,
    outlines)."""
    rng = np.random.default_rng(seed)
    y = np.arange(-3.5, 3.5, 0.02)
    pts, line = [], []
    for k, x in enumerate(np.arange(-3.5, 3.5, spacing)):
        xy = np.column_stack([np.full(len(y), x), y])
        removed = np.zeros(len(y))
        for su, sv, centre, turn, depth in pockets:
            a = np.radians(turn)
            q = (xy - centre) @ np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
            inside = np.minimum(su / 2 - np.abs(q[:, 0]), sv / 2 - np.abs(q[:, 1]))
            removed = np.maximum(removed, np.clip(inside / TAPER, 0, 1) * depth)
        z = 5.0 + 0.01 * xy[:, 0] - removed + noise * rng.standard_normal(len(y))
        pts.append(np.column_stack([xy, z]))
        line.append(np.full(len(y), k))
    outlines = [shapely.affinity.translate(shapely.affinity.rotate(
        shapely.box(-su / 2, -sv / 2, su / 2, sv / 2), turn, origin=(0, 0)), *centre)
        for su, sv, centre, turn, _ in pockets]
    return np.vstack(pts), np.concatenate(line), outlines


def _corner_error(found, truth) -> float:
    """The largest distance (mm) of a found corner from the nearest corner of ``truth``'s
    half-depth outline (half the taper inside it)."""
    half = np.asarray(truth.buffer(-TAPER / 2, join_style="mitre").exterior.coords)[:4]
    got = np.asarray(found.exterior.coords)[:-1]
    return max(np.min(np.linalg.norm(half - c, axis=1)) for c in got)


def test_turned_pockets_are_outlined_on_their_walls_and_measured():
    """Pockets turned 20° and −35°, 0.05 and 0.5 mm deep: each found once, its corners within
    20 µm of the half-depth outline (the cells above the noise instead of those deeper than
    half the floor: 176–200 µm), its depth as with the true outline."""
    for turn, depth, seed in ((20.0, 0.05, 3), (-35.0, 0.5, 4)):
        pts, line, (truth,) = _cloud([(2.0, 2.0, (0.3, -0.2), turn, depth)], seed=seed)
        (found,) = find_pockets(pts, line)
        assert len(np.asarray(found.exterior.coords)) == 5
        assert _corner_error(found, truth) < 0.02, (turn, found)
        scan = DepthScan(pts, line, None, "plane")
        mine, given = measure_pockets(scan, [found, truth], 0.005)
        assert abs(mine.mean_mm - depth) < 3 * mine.sem_mm
        assert abs(mine.mean_mm - given.mean_mm) < mine.sem_mm


def test_small_dips_and_noise_are_not_pockets_and_other_shapes_keep_their_own_outline():
    """A 0.6 × 0.6 mm dip (0.36 mm², under 0.5) and the top's noise are not found; an L of two
    pockets is outlined as itself, not as a rectangle around it."""
    pts, line, _ = _cloud([(0.6, 0.6, (0.0, 0.0), 0.0, 0.1)])
    assert find_pockets(pts, line) == []
    pts, line, (a, b) = _cloud([(3.0, 1.0, (0.0, -1.0), 0.0, 0.1),
                                (1.0, 3.0, (-1.0, 0.0), 0.0, 0.1)])
    (found,) = find_pockets(pts, line)
    ell = a.union(b)
    assert found.symmetric_difference(ell).area < 0.15 * ell.area
    assert len(np.asarray(found.exterior.coords)) > 5


def test_without_pockets_the_command_finds_and_measures_them(tmp_path):
    pts, line, _ = _cloud([(2.0, 2.0, (0.0, 0.0), 25.0, 0.2)])
    write_ply(tmp_path / "cloud.ply", PointCloud(pts, {"line": line.astype(np.int32)}))
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "cloud.ply"), "-o",
                                   str(tmp_path / "report")])
    assert run.exit_code == 0, run.output
    (got,) = json.loads((tmp_path / "report" / "depth.json").read_text())["pockets"]
    assert len(got["outline"]) == 4 and abs(got["depth_mm"] - 0.2) < 3 * got["sigma_mm"]
    flat, line, _ = _cloud([])
    write_ply(tmp_path / "flat.ply", PointCloud(flat, {"line": line.astype(np.int32)}))
    run = CliRunner().invoke(app, ["depth", str(tmp_path / "flat.ply")])
    assert run.exit_code == 1 and "no pocket found" in run.output


def test_a_pocket_over_a_large_share_of_the_scan_is_still_found():
    """A 4 × 4 mm pocket on a 7 × 7 mm scan (a third of its points): the top's plane fit,
    pulled down by it at first, keeps the top about its median residual, so the outline
    lies where the depth crosses half the pocket's (within two raster cells; about the
    plane's own zero instead, 0.11 mm off)."""
    pts, line, (outline,) = _cloud([(4.0, 4.0, np.array([0.0, 0.0]), 0.0, 0.1)])
    (found,) = find_pockets(pts, line)
    assert found.hausdorff_distance(outline) < 0.09, found
