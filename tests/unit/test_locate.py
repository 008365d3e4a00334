"""Locating a part: poses recovered from synthetic scans of a known pose and from a small
simulated scan; refusals (no part, only part of it, a symmetric part without a breaker, the
wrong part) that never give a pose; POSE.json and ``insitu locate``."""

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.errors import ConfigError
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.formats.pose import load_pose
from insitu.locate.part import LocateRefused, locate_part
from insitu.locate.reference import reference_from_cloud, reference_from_mesh
from insitu.sim.scene import Scene
from insitu.sim.workpieces import make_workpiece

runner = CliRunner()
DATA = Path(__file__).resolve().parents[1] / "data"


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def synthetic_scan(name, pose, region=None, noise=0.01, seed=1, spacing=0.5):
    """A top-down scan of ``name`` at ``pose`` on the table: lines along y ``spacing`` mm
    apart, points 0.1 mm apart along them, Gaussian noise; (points (N, 3), line index
    (N,))."""
    part = make_workpiece(name, x=pose[0], y=pose[1], angle_deg=pose[2])
    scene = Scene([make_workpiece("table"), part])
    lo, hi = part.bounds()
    x0, x1, y0, y1 = region or (lo[0] - 3, hi[0] + 3, lo[1] - 6, hi[1] + 6)
    xs, ys = np.arange(x0, x1, spacing), np.arange(y0, y1, 0.1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    rays = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, 50.0)])
    hits = scene.cast(rays, np.tile([0.0, 0.0, -1.0], (len(rays), 1)))
    rng = np.random.default_rng(seed)
    pts = hits.points[hits.hit] + rng.normal(0, noise, (hits.hit.sum(), 3))
    lines = np.repeat(np.arange(len(xs)), len(ys))[hits.hit]
    return pts, lines


@pytest.fixture(scope="module")
def refs():
    out = {}
    for name in ("step-block", "arc", "insert"):
        w = make_workpiece(name)
        out[name] = reference_from_mesh(w.vertices, w.triangles, name)
    return out


def _err(pose, truth):
    b = pose.best
    turn = abs((b.angle_deg - truth[2] + 180) % 360 - 180)
    return np.hypot(b.x_mm - truth[0], b.y_mm - truth[1]), turn


@pytest.mark.parametrize("truth", [(12.0, -7.0, 33.0), (-20.0, 15.0, -121.5),
                                   (4.0, 22.0, 165.0)])
def test_pose_of_a_synthetic_scan_is_recovered(refs, truth):
    pts, lines = synthetic_scan("step-block", truth)
    pose = locate_part(refs["step-block"], pts, lines=lines)
    mm, deg = _err(pose, truth)
    assert mm < 0.02 and deg < 0.02, (mm, deg)
    assert abs(pose.best.z_mm) < 0.01 and pose.table_z_mm == pytest.approx(0.0, abs=0.01)
    T = pose.T_world_part
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and T[2, 2] == 1.0
    assert pose.best.fitness > 0.95 and pose.best.coverage > 0.95


def test_the_edge_step_is_what_makes_it_precise(refs):
    """Without the scan lines (no edges) flat tops leave x, y to the ICP: worse, and with no
    σ to hold it to the tolerance, refused — saying what would give it."""
    truth = (12.0, -7.0, 33.0)
    pts, lines = synthetic_scan("step-block", truth)
    with_edges = _err(locate_part(refs["step-block"], pts, lines=lines), truth)
    with pytest.raises(LocateRefused, match="records no scan lines.*insitu scan") as e:
        locate_part(refs["step-block"], pts)
    b = e.value.best
    without = np.hypot(b.x_mm - truth[0], b.y_mm - truth[1])
    assert with_edges[0] < 0.02 and without > 2 * with_edges[0]


def test_a_part_square_to_the_lines_is_refused_or_right(refs):
    """Lying square, the block's long edges run along the scan lines: only its corners and
    ends hold x. The pose is right, or refused as not pinned down — never a guess."""
    truth = (5.0, 3.0, 0.0)
    pts, lines = synthetic_scan("step-block", truth, noise=0.03)
    try:
        mm, deg = _err(locate_part(refs["step-block"], pts, lines=lines), truth)
    except LocateRefused as e:
        assert e.reason == "poor-fit" and "not pinned down" in str(e)
    else:
        assert mm < 0.05 and deg < 0.05


def test_edges_along_the_lines_do_not_pin_the_pose(refs):
    """The uncertainty check itself: with the samples of one edge direction only, the
    shift across them is free — refused."""
    from insitu.locate.part import LocateSettings
    truth = (5.0, 3.0, 0.0)
    pts, lines = synthetic_scan("step-block", truth)
    with pytest.raises(LocateRefused, match="not pinned down"):
        locate_part(refs["step-block"], pts, LocateSettings(tolerance_mm=1e-4), lines=lines)


def test_no_part_is_refused(refs):
    g = np.meshgrid(np.arange(-30, 30, 0.5), np.arange(-30, 30, 0.2))
    table = np.column_stack([g[0].ravel(), g[1].ravel(), np.zeros(g[0].size)])
    with pytest.raises(LocateRefused, match="no part in the scan") as e:
        locate_part(refs["step-block"], table)
    assert e.value.reason == "no-part"


def test_a_part_only_partly_scanned_is_refused(refs):
    truth = (0.0, 0.0, 90.0)                     # the block lies along x: scan half of it
    pts, lines = synthetic_scan("step-block", truth, region=(-45, 5, -14, 14))
    with pytest.raises(LocateRefused, match="only partly in the scan") as e:
        locate_part(refs["step-block"], pts, lines=lines)
    assert e.value.reason == "partial"


def test_the_wrong_part_is_not_found(refs):
    pts, lines = synthetic_scan("insert", (3.0, -4.0, 20.0))
    with pytest.raises(LocateRefused) as e:
        locate_part(refs["step-block"], pts, lines=lines)
    assert e.value.reason in ("no-part", "poor-fit", "partial")


@pytest.mark.parametrize("name, fold", [("arc", 2), ("insert", 3)])
def test_a_symmetric_part_is_refused_without_a_breaker(refs, name, fold):
    truth = (-6.0, 9.0, 47.0)
    pts, lines = synthetic_scan(name, truth, spacing=0.25)     # as a recipe scans a small part
    with pytest.raises(LocateRefused, match="ambiguous: .* and .* fit nearly equally") as e:
        locate_part(refs[name], pts, lines=lines)
    assert e.value.reason == "ambiguous"
    # the window picks exactly one of the symmetric poses: the right one (the small
    # insert's turn is known to 0.09° (1σ): its bound lifted)
    from insitu.locate.part import LocateSettings
    loose = LocateSettings(turn_bound_deg=0.5)
    pose = locate_part(refs[name], pts, loose, lines=lines,
                       prefer_angle=(truth[2] - 40, truth[2] + 40))
    mm, deg = _err(pose, truth)
    assert mm < 0.03 and deg < 0.05
    assert pose.second is not None and pose.second.score > pose.best.score - 0.05
    turned = abs((pose.second.angle_deg - pose.best.angle_deg) % (360 / fold))
    assert min(turned, 360 / fold - turned) < 1.0
    with pytest.raises(LocateRefused, match="no well-fitting pose turned within") as e:
        locate_part(refs[name], pts, lines=lines, prefer_angle=(truth[2] + 60 / fold,
                                                                 truth[2] + 60 / fold + 1))
    assert e.value.reason == "not-preferred"


def test_a_first_scan_as_reference(refs):
    """The reference is a scan at one pose: the pose found in another is the move between.
    Its edges are only as sharp as its lines (0.5 mm apart), so the edge step may not pin the
    pose: then it is refused — never a pose far off."""
    from insitu.locate.part import LocateSettings
    first, _ = synthetic_scan("step-block", (0.0, 0.0, 30.0), seed=2)
    ref = reference_from_cloud(first, "first.ply")
    assert ref.kind == "cloud" and ref.base_z_mm == pytest.approx(0.0, abs=0.02)
    truth = (10.0, -5.0, 55.0)                  # 25° further and shifted
    pts, lines = synthetic_scan("step-block", truth)
    try:
        loose = LocateSettings(tolerance_mm=0.2, turn_bound_deg=0.5)
        pose = locate_part(ref, pts, loose, lines=lines)
    except LocateRefused as e:
        assert e.reason in ("poor-fit", "ambiguous")
        assert "25." in str(e) or "24." in str(e) or "23." in str(e)   # it was close
        return
    # the reference frame is the first scan's world: the part turned 25° more in it
    assert abs((pose.best.angle_deg - 25 + 180) % 360 - 180) < 0.5
    R = pose.T_world_part[:2, :2]
    c, s_ = np.cos(np.radians(25)), np.sin(np.radians(25))
    assert np.allclose(R, [[c, -s_], [s_, c]], atol=1e-2)
    assert np.hypot(pose.best.x_mm - 10, pose.best.y_mm + 5) < 0.5


def test_locate_command_writes_pose_json(tmp_path, refs):
    truth = (8.0, -3.0, -64.0)
    pts, lines = synthetic_scan("step-block", truth)
    write_ply(tmp_path / "scan.ply", PointCloud(pts, {"line": lines}))
    res = _run("sim", "export-part", "step-block", "-o", tmp_path / "sb.stl")
    assert res.exit_code == 0, res.output
    res = _run("locate", tmp_path / "sb.stl", tmp_path / "scan.ply", "-o", tmp_path / "p.json")
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "p.json").read_text())
    assert d["schema_version"] == 1 and d["kind"] == "part-pose"
    assert d["inputs"] == [str(tmp_path / "sb.stl"), str(tmp_path / "scan.ply")]
    assert np.hypot(d["x_mm"] - truth[0], d["y_mm"] - truth[1]) < 0.02
    pose = load_pose(tmp_path / "p.json")
    assert np.allclose(pose.matrix[:2, 3], [d["x_mm"], d["y_mm"]])
    # with the height calibration's camera (here not the one this scan was made through:
    # the gaps it reads are nonsense, and the fit still holds)
    res = _run("locate", tmp_path / "sb.stl", tmp_path / "scan.ply", "-o", tmp_path / "c.json",
               "--height-cal", DATA / "height-cal-b2.json")
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "c.json").read_text())
    assert np.hypot(d["x_mm"] - truth[0], d["y_mm"] - truth[1]) < 0.02
    # refused: one line, exit 1, nothing written
    res = _run("locate", tmp_path / "sb.stl", tmp_path / "scan.ply", "-o",
               tmp_path / "q.json", "--prefer-angle", 100, 120)
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1
    assert "no well-fitting pose" in res.output and not (tmp_path / "q.json").exists()


def test_pose_json_refuses_a_tilted_pose(tmp_path):
    good = {"schema_version": 1, "kind": "part-pose", "x_mm": 0, "y_mm": 0, "z_mm": 0,
            "angle_deg": 0, "fitness": 1, "coverage": 1, "inlier_rmse_mm": 0.02,
            "T_world_part": np.eye(4).tolist()}
    (tmp_path / "ok.json").write_text(json.dumps(good))
    assert np.allclose(load_pose(tmp_path / "ok.json").matrix, np.eye(4))
    tilted = np.eye(4)
    c, s = np.cos(0.1), np.sin(0.1)
    tilted[1:3, 1:3] = [[c, -s], [s, c]]
    (tmp_path / "bad.json").write_text(json.dumps({**good, "T_world_part": tilted.tolist()}))
    with pytest.raises(ConfigError, match="bad.json: T_world_part: expected a turn about z"):
        load_pose(tmp_path / "bad.json")
    (tmp_path / "far.json").write_text(json.dumps({**good, "fitness": 1.5}))
    with pytest.raises(ConfigError, match="fitness: 1.5 is outside 0 … 1"):
        load_pose(tmp_path / "far.json")


def test_pose_of_a_small_simulated_scan(refs):
    """A real (simulated) scan at binning 4: found where it lies, within the rig's own
    calibration offset (~0.1 mm) and the coarse frame's precision; the default precision
    check refuses it as too coarse, naming the numbers."""
    from insitu.locate.part import LocateSettings
    from insitu.services import scan_live
    from insitu.services.locate import locate_cloud
    from insitu.services.station import simulated
    from insitu.sim.world import sim_world

    truth = (8.0, -6.0, 140.0)
    with simulated(sim_world("step-block", binning=4, pose=truth)) as station:
        cloud = scan_live(station).cloud
    with pytest.raises(LocateRefused, match="not pinned down .* what would pin it down: "
                                            "a crossed pass .*, the room-light frame"):
        locate_cloud(refs["step-block"], cloud)
    loose = LocateSettings(tolerance_mm=0.2, turn_bound_deg=0.5)
    pose = locate_cloud(refs["step-block"], cloud, loose)
    mm, deg = _err(pose, truth)
    assert mm < 0.2 and deg < 0.15, (mm, deg)
    assert pose.best.edges > 50


def test_edges_that_are_not_the_references_are_refused(refs):
    """When a good share of the scan's edges finds no edge of the reference where the pose
    puts them, the edge step gives up (the pose would be doubtful)."""
    from insitu.geometry.pose import apply, inverse, rot_z
    from insitu.locate.edge_align import align_edges, edge_samples

    truth = (12.0, -7.0, 33.0)
    pts, lines = synthetic_scan("step-block", truth)
    found = edge_samples(pts, lines, pts[:, 2] < 0.5)
    e, u = found.points, found.dirs
    pose = inverse((np.radians(truth[2]), np.array([truth[0], truth[1], 0.0])))
    ep, up = apply(pose, e), u @ rot_z(pose[0])[:2, :2].T
    assert align_edges(refs["step-block"].heights, ep, up).samples > 0.9 * len(e)
    inside = ep.copy()                      # the same samples moved to the middle of a step
    inside[:, :2] = [0.0, 30.0]
    inside[:, 2] = 15.0
    mixed = np.vstack([ep, inside]), np.vstack([up, up])
    assert align_edges(refs["step-block"].heights, *mixed) is None


def test_the_command_holds_the_pose_to_its_tolerance(tmp_path, refs):
    """POSE.json carries the pose's 1σ at the rim and the tolerance it was held to; a
    tolerance its edges cannot give is refused (nothing written), saying what would."""
    truth = (8.0, -3.0, -64.0)
    pts, lines = synthetic_scan("step-block", truth)
    write_ply(tmp_path / "scan.ply", PointCloud(pts, {"line": lines}))
    res = _run("sim", "export-part", "step-block", "-o", tmp_path / "sb.stl")
    res = _run("locate", tmp_path / "sb.stl", tmp_path / "scan.ply", "-o", tmp_path / "p.json")
    assert res.exit_code == 0, res.output
    d = json.loads((tmp_path / "p.json").read_text())
    assert 0 < 2 * d["sigma_rim_mm"] <= d["tolerance_mm"] == 0.05 and d["turn_bound_deg"] == 0.1
    res = _run("locate", tmp_path / "sb.stl", tmp_path / "scan.ply", "-o", tmp_path / "q.json",
               "--tolerance", 0.001)
    assert res.exit_code == 1 and not (tmp_path / "q.json").exists()
    flat = " ".join(res.output.split())
    assert "not pinned down to the tolerance" in flat and "what would pin it down" in flat
