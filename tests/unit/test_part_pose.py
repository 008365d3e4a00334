"""Parts at any pose: the simulated rig places them (truth.json records T_world_part), a
cloud's rig record carries the pose (another pose is another placement), and ``insitu mark
--part-pose`` takes --at and --rotate in the part's frame."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.errors import FormatError, SafetyError
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.formats.rig_record import describe, parse, same_rig
from insitu.marking import Placement, read_job
from insitu.services.station import connect
from insitu.sim.workpieces import make_workpiece, part_matrix, random_pose
from insitu.sim.world import sim_world

runner = CliRunner()
SQUARE = ('<svg xmlns="http://www.w3.org/2000/svg" width="4mm" height="2mm" '
          'viewBox="0 0 4 2"><rect x="0" y="0" width="4" height="2" fill="black"/></svg>')


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def _T(x, y, deg):
    a = np.radians(deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:2, 3] = x, y
    return T


def test_part_placement_moves_the_part_frame_to_the_world():
    T = _T(10.0, -5.0, 30.0)
    p = Placement("text:A", (2.0, 1.0), 5.0, rotate_deg=15.0, hatch_angle_deg=5.0).in_world(T)
    assert np.allclose(p.at_mm, (T @ [2.0, 1.0, 0.0, 1.0])[:2])
    assert p.rotate_deg == pytest.approx(45.0) and p.hatch_angle_deg == pytest.approx(35.0)
    assert p.width_mm == 5.0 and p.pattern == "text:A"


def test_mark_with_part_pose_places_in_the_part_frame(tmp_path):
    """The job's marks land where the part's frame says, turned with the part."""
    (tmp_path / "sq.svg").write_text(SQUARE)
    g = np.meshgrid(np.arange(-20, 20.01, 0.2), np.arange(-20, 20.01, 0.2))
    pts = np.column_stack([g[0].ravel(), g[1].ravel(), np.full(g[0].size, 5.0)])
    write_ply(tmp_path / "c.ply", PointCloud(pts))
    T = _T(3.0, -4.0, 90.0)
    pose = {"schema_version": 1, "kind": "part-pose", "T_world_part": T.tolist(), "x_mm": 3.0,
            "y_mm": -4.0, "z_mm": 0.0, "angle_deg": 90.0, "fitness": 1.0, "coverage": 1.0,
            "inlier_rmse_mm": 0.02, "inputs": ["part.stl", "c.ply"]}
    (tmp_path / "pose.json").write_text(json.dumps(pose))
    res = _run("mark", "--cloud", tmp_path / "c.ply", "--pattern", tmp_path / "sq.svg",
               "--at", 5.0, 0.0, "--width", 4, "--part-pose", tmp_path / "pose.json",
               "-o", tmp_path / "job.json")
    assert res.exit_code == 0, res.output
    assert "part pose" in res.output
    xy = np.vstack([p.points[:, :2] for p in read_job(tmp_path / "job.json").paths])
    # part (5, 0) is world (3, 1); the 4 × 2 mm square turned 90°: 2 wide in x, 4 in y
    assert np.allclose((xy.min(0) + xy.max(0)) / 2, (3.0, 1.0), atol=0.05)
    assert np.allclose(xy.max(0) - xy.min(0), (2.0, 4.0), atol=0.1)
    # a pose located on another cloud is said so
    (tmp_path / "pose2.json").write_text(json.dumps({**pose, "inputs": ["p.stl", "x.ply"]}))
    res = _run("mark", "--cloud", tmp_path / "c.ply", "--pattern", tmp_path / "sq.svg",
               "--at", 5.0, 0.0, "--width", 4, "--part-pose", tmp_path / "pose2.json",
               "-o", tmp_path / "job2.json")
    assert res.exit_code == 0 and "was located on x.ply" in res.output


def test_sim_parts_at_a_pose_and_their_truth():
    world = sim_world("arc", pose=(10.0, -5.0, 30.0))
    part = world.parts[0]
    assert np.allclose(part_matrix(part), _T(10.0, -5.0, 30.0))
    truth = world.truth()["workpieces"][0]
    assert np.allclose(truth["T_world_part"], _T(10.0, -5.0, 30.0))
    # the crest (part x = 0) runs along the turned y axis
    top = part.height(10.0 - 15 * np.sin(np.radians(30)), -5.0 + 15 * np.cos(np.radians(30)))
    assert top == pytest.approx(11.5, abs=1e-6)
    world.place_part((0.0, 0.0, 0.0))
    assert np.allclose(world.parts[0].vertices, make_workpiece("arc").vertices)
    rng = np.random.default_rng(0)
    poses = np.array([random_pose(rng) for _ in range(200)])
    assert np.all(np.abs(poses[:, :2]) <= 25) and np.all(np.abs(poses[:, 2]) <= 180)
    assert poses[:, 2].min() < -150 and poses[:, 2].max() > 150


def test_the_rig_record_carries_the_pose(tmp_path):
    at = {"workpiece": "arc", "seed": 0, "binning": 1, "pose": [10.0, -5.0, 30.0]}
    origin = {"workpiece": "arc", "seed": 0, "binning": 2}
    assert not same_rig(at, origin)
    assert same_rig(origin, {**origin, "pose": [0.0, 0.0, 0.0]})
    assert same_rig(at, {**at, "binning": 4})
    assert "at x 10 y -5 mm turned 30°" in describe(at)
    with pytest.raises(FormatError, match="pose"):
        parse(tmp_path / "c.ply", "header", {**at, "pose": [1.0, "x", 2.0]})
    with connect(workpiece="arc", pose=(10.0, -5.0, 30.0)) as station:
        assert station.record["pose"] == [10.0, -5.0, 30.0]
        with pytest.raises(SafetyError, match="turned 30°.*; nothing marked"):
            station.check_source(tmp_path / "c.ply", origin | {"binning": 1}, "cloud")
        assert station.check_source(tmp_path / "c.ply", at, "cloud") is None
    with connect(workpiece="arc") as station:
        assert "pose" not in station.record


def test_pose_option_on_the_simulated_commands(tmp_path):
    res = _run("sim", "record", "height-calibration", "-o", tmp_path / "h", "--pose", 1, 2, 3)
    assert res.exit_code == 1 and "--pose places the part for a scan" in res.output
    res = _run("scan", "-o", tmp_path / "c.ply", "--pose", 2000, 0, 0)
    assert res.exit_code == 1 and "--pose: 2000 is outside" in res.output
