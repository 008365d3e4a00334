"""The production recipe: written and read back whole (paths relative to it), every field
validated with one line naming it, placements moved by a part's pose, and the commands that
make and show one."""

import json
import math
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.errors import FormatError
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.formats.recipe import Recipe, RecipeScan, read_recipe, reference_kind, write_recipe
from insitu.geometry.pose import pose_matrix
from insitu.marking import Placement
from insitu.marking.modes import PROJECTIONS
from insitu.sim.feeder import part_pose

runner = CliRunner()


def _flat(output: str) -> str:
    return " ".join(re.sub(r"[│┃┌┐└┘├┤┬┴┼─]", " ", output).split())


@pytest.fixture
def reference(tmp_path):
    """A first scan's cloud: a 6 × 6 mm block 3 mm high on the table (no scan lines)."""
    path = tmp_path / "ref.ply"
    g = np.meshgrid(np.arange(-10, 10.01, 0.5), np.arange(-10, 10.01, 0.5))
    x, y = g[0].ravel(), g[1].ravel()
    write_ply(path, PointCloud(np.column_stack([x, y, np.where(
        (np.abs(x) <= 3) & (np.abs(y) <= 3), 3.0, 0.0)])))
    return path


def _recipe(reference, **kw):
    return Recipe(reference=reference, reference_kind="cloud",
                  placements=(Placement('qr:"{serial:05d}"', (1.0, 20.0), 8.0, 15.0),
                              Placement("text:LOT;size=2", (0.0, -20.0), 6.0, 0.0, "wrap",
                                        0.05, 30.0)), **kw)


def test_a_recipe_reads_back_as_written(tmp_path, reference):
    sub = tmp_path / "recipes"
    sub.mkdir()
    r = _recipe(reference, scan=RecipeScan((-40, 40, -60, 60), 4.0, 0.4, lines_per_frame="auto",
                                           survey_mm=4.0),
                prefer_angle_deg=(-90.0, 90.0), serial_start=100, fields={"lot": "A7"},
                workpiece="step-block")
    path = sub / "r.json"
    write_recipe(path, r)
    raw = json.loads(path.read_text())
    assert raw["format"] == "insitu-recipe/1" and raw["schema_version"] == 1
    assert raw["reference"] == {"cloud": "../ref.ply"}
    assert raw["serial"]["counter"] == "serial.counter.json"
    back = read_recipe(path, Placement, PROJECTIONS)
    assert back.reference == reference and back.reference_kind == "cloud"
    assert back.placements == r.placements
    assert back.scan == r.scan and back.prefer_angle_deg == (-90.0, 90.0)
    assert raw["scan"]["lines_per_frame"] == "auto" and back.scan.lines_per_frame == "auto"
    assert raw["scan"]["survey_mm"] == 4.0 and back.scan.survey_mm == 4.0
    assert back.counter == sub / "serial.counter.json" and back.serial_start == 100
    assert back.fields == {"lot": "A7"} and back.workpiece == "step-block"
    assert back.laser == r.laser


@pytest.mark.parametrize("change, message", [
    (lambda d: d["placements"][0].update(width_mm=-1),
     r"placements\[0\]\.width_mm: -1 is outside 0\.001 … 2000 mm"),
    (lambda d: d["laser"].update(power_pct=120), r"laser\.power_pct: 120 is outside 0 … 100 %"),
    (lambda d: d["scan"].update(margin_mm=0), r"scan\.margin_mm: 0 is outside"),
    (lambda d: d["scan"].update(lines_per_frame=0), r"scan\.lines_per_frame"),
    (lambda d: d["scan"].update(lines_per_frame="many"), r"scan\.lines_per_frame"),
    (lambda d: d["scan"].update(survey_mm=0), r"scan\.survey_mm: 0 is outside"),
    (lambda d: d.update(reference={"mesh": "a.stl", "cloud": "b.ply"}),
     r"reference: expected exactly one of mesh, cloud"),
    (lambda d: d.update(reference={"cloud": "gone.ply"}), r"reference\.cloud: gone\.ply not found"),
    (lambda d: d["placements"][0].update(mode="melt"),
     r"placements\[0\]\.mode: expected 'planar' or 'wrap', got 'melt'"),
    (lambda d: d.update(placements=[]), r"placements"),
    (lambda d: d["serial"].update(start=-3), r"serial\.start"),
    (lambda d: d.update(colour="red"), r"colour"),
    (lambda d: d.update(format="insitu-project/1"), r"format: expected 'insitu-recipe/1'"),
    (lambda d: d.update(schema_version=9), r"schema_version 9: this version of insitu reads"),
])
def test_each_bad_field_is_one_line_naming_it(tmp_path, reference, change, message):
    path = tmp_path / "r.json"
    write_recipe(path, _recipe(reference))
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))
    with pytest.raises(FormatError, match=message) as e:
        read_recipe(path, Placement, PROJECTIONS)
    assert "\n" not in str(e.value) and str(path) in str(e.value)


def test_reference_kind_tells_a_mesh_from_a_cloud(tmp_path, reference):
    assert reference_kind(reference) == "cloud"
    mesh = tmp_path / "m.ply"
    mesh.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y"
                    "\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                    "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    assert reference_kind(mesh) == "mesh"
    assert reference_kind(tmp_path / "part.stl") == "mesh"
    with pytest.raises(FormatError, match=r"part\.step: expected a mesh"):
        reference_kind(tmp_path / "part.step")


def test_a_placement_moves_with_the_part():
    p = Placement("qr:x", (10.0, 0.0), 5.0, 15.0, hatch_mm=0.1, hatch_angle_deg=5.0)
    T = pose_matrix(3.0, -4.0, 90.0)
    w = p.in_world(T)
    assert w.at_mm == pytest.approx((3.0, 6.0))
    assert w.rotate_deg == pytest.approx(105.0) and w.hatch_angle_deg == pytest.approx(95.0)
    assert (w.pattern, w.width_mm, w.mode, w.hatch_mm) == ("qr:x", 5.0, "planar", 0.1)
    # the pattern placed in the world is the part-frame pattern moved by the pose
    part, world = p.placed(), w.placed()
    moved = (T[:2, :2] @ np.vstack(part.paths or part.contours).T).T + T[:2, 3]
    assert np.vstack(world.paths or world.contours) == pytest.approx(moved, abs=1e-9)
    back = w.in_world(np.linalg.inv(T))
    assert back.at_mm == pytest.approx(p.at_mm) and back.rotate_deg == pytest.approx(15.0)


def test_random_poses_are_reproducible_and_in_range():
    poses = [part_pose(5, k) for k in range(1, 41)]
    assert poses == [part_pose(5, k) for k in range(1, 41)]
    xy = np.array([p[:2] for p in poses])
    assert np.abs(xy).max() <= 25.0 and np.ptp(xy, axis=0).min() > 25.0
    assert np.ptp([p[2] for p in poses]) > 270.0
    assert part_pose(None, 3) == (0.0, 0.0, 0.0)
    T = pose_matrix(*poses[0])
    assert math.degrees(math.atan2(T[1, 0], T[0, 0])) % 360 == pytest.approx(poses[0][2])


def test_recipe_new_add_and_show(tmp_path, reference):
    out = tmp_path / "r.json"
    res = runner.invoke(app, ["recipe", "new", str(reference), "--pattern", 'qr:"{serial}"',
                              "--at", "1", "2", "--width", "6", "--rotate", "30", "-o", str(out),
                              "--serial-start", "7", "--prefer-angle", "0", "180",
                              "--workpiece", "step-block", "--lines-per-frame", "4"])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["recipe", "add", str(out), "--pattern", "text:LOT;size=2",
                              "--at", "0", "-20"])
    assert res.exit_code == 0, res.output
    r = read_recipe(out, Placement, PROJECTIONS)
    assert [p.at_mm for p in r.placements] == [(1.0, 2.0), (0.0, -20.0)]
    assert r.serial_start == 7 and r.prefer_angle_deg == (0.0, 180.0)
    assert r.scan.lines_per_frame == 4
    res = runner.invoke(app, ["recipe", "show", str(out)])
    assert res.exit_code == 0, res.output
    flat = _flat(res.output)
    assert 'placement 1 qr:"{serial}" at (1, 2), 6 mm, 30°, planar' in flat
    assert "keep the turn within 0 … 180°" in flat and "first serial 7" in flat


def test_recipe_new_refuses_a_pattern_that_does_not_load(tmp_path, reference):
    res = runner.invoke(app, ["recipe", "new", str(reference), "--pattern", "qr:{nope}",
                              "--at", "0", "0", "-o", str(tmp_path / "r.json")])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit)
    assert "nope" in res.output and not (tmp_path / "r.json").exists()
    res = runner.invoke(app, ["recipe", "new", str(reference), "--pattern", "qr:A", "--at",
                              "0", "0", "-o", str(tmp_path / "r.json"), "--lines-per-frame", "0"])
    assert res.exit_code == 1 and "--lines-per-frame '0'" in res.output
    assert "reference" not in res.output
    assert not (tmp_path / "r.json").exists()


def test_a_mesh_reference_is_sampled_in_the_part_frame(tmp_path):
    import open3d as o3d

    from insitu.services.locate import recipe_locator
    from insitu.sim.workpieces import make_workpiece

    part = make_workpiece("step-block")
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(part.vertices)),
                                     o3d.utility.Vector3iVector(np.array(part.triangles)))
    mesh.compute_triangle_normals()
    path = tmp_path / "step.stl"
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    assert reference_kind(path) == "mesh"
    ref = recipe_locator(Recipe(path, "mesh", (Placement("text:A", (0.0, 0.0), 2.0),))).reference
    assert ref.kind == "mesh" and len(ref.points) > 1000
    lo, hi = part.bounds()
    assert (ref.points.min(0) >= lo - 1e-6).all() and (ref.points.max(0) <= hi + 1e-6).all()
    (tmp_path / "empty.obj").write_text("# nothing\n")
    with pytest.raises(FormatError, match=r"empty\.obj: no triangles"):
        recipe_locator(Recipe(tmp_path / "empty.obj", "mesh", ()))


def test_recipe_new_reports_a_scan_references_outline(tmp_path, reference):
    """A scan reference without its room-light frame: the recipe is written, with a warning
    saying what would place its parts within 0.05 mm; the frame without the camera it was
    taken through is refused; the tolerance is kept."""
    out = tmp_path / "r.json"
    res = runner.invoke(app, ["recipe", "new", str(reference), "--pattern", "text:A;size=2",
                              "--at", "0", "0", "-o", str(out), "--tolerance", "0.08",
                              "--turn-tolerance", "0.03"])
    assert res.exit_code == 0, res.output
    flat = _flat(res.output)
    assert "its scan lines' ends only" in flat and "--reference-room-light" in flat
    assert re.search(r"the scan shows \d+% of the part's top", flat), flat
    back = read_recipe(out, Placement, PROJECTIONS)
    assert back.tolerance == (0.08, 0.1) and back.reference_room_light is None
    assert back.turn_tolerance_deg == 0.03
    assert json.loads(out.read_text())["locate"]["turn_tolerance_deg"] == 0.03
    res = runner.invoke(app, ["recipe", "new", str(reference), "--pattern", "text:A;size=2",
                              "--at", "0", "0", "-o", str(tmp_path / "s.json"),
                              "--reference-room-light", str(tmp_path / "room.png")])
    assert res.exit_code == 1 and "needs --height-cal" in res.output
    assert not (tmp_path / "s.json").exists()


def test_a_scan_references_room_light_frame_reads_back(tmp_path, reference):
    frame = tmp_path / "room.png"
    frame.write_bytes(b"")
    path = tmp_path / "r.json"
    write_recipe(path, _recipe(reference, reference_room_light=frame, tolerance=(0.03, 0.2)))
    raw = json.loads(path.read_text())
    assert raw["reference"] == {"cloud": "ref.ply", "room_light": "room.png"}
    assert raw["locate"]["tolerance_mm"] == 0.03 and raw["locate"]["turn_bound_deg"] == 0.2
    back = read_recipe(path, Placement, PROJECTIONS)
    assert back.reference_room_light == frame and back.tolerance == (0.03, 0.2)
    assert raw["locate"]["turn_tolerance_deg"] is None and back.turn_tolerance_deg is None
