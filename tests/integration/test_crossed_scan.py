"""The crossed pass: a height calibration that also knows lines at 45° to x (the sheet model
fitted in the world turned a quarter-turn's half), scans with a second, crossed pass, and a
part whose edges run along the first pass's lines located from the crossed one."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.calibrate.height_fit import LineObservation, fit_turned_sheet
from insitu.cli.main import app
from insitu.errors import MeasurementError
from insitu.formats.calibration import HeightCalibration
from insitu.formats.json_file import load_json_model
from insitu.formats.sequence import Sequence
from insitu.geometry.beams import light_plane
from insitu.locate.edge_align import edge_samples
from insitu.reconstruct.plan import scan_lines
from insitu.reconstruct.turned_sheet import (
    CROSS_ANGLE_DEG,
    TurnedSheetModel,
    line_angle,
    turned_lines,
    turned_offset,
)
from insitu.services import calibrate_height, load_height_calibration, scan_live
from insitu.services.record import record_height_calibration
from insitu.services.station import connect, simulated
from insitu.sim.scene import Scene
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import sim_world

DATA = Path(__file__).parent.parent / "data"


@pytest.fixture(scope="module")
def crossed_cal(crossed_height_cal):
    """The height calibration recorded with crossed lines (tests/integration/conftest.py)."""
    return load_height_calibration(crossed_height_cal / "height.json")


def _in_pass(cloud, angle):
    """(N,) bool: the points of the lines at ``angle`` degrees to x, by each line's points'
    direction."""
    line = cloud.attributes["line"]
    keep = np.zeros(len(line), bool)
    for i in np.unique(line):
        sel = line == i
        xy = cloud.points[sel, :2]
        d = np.linalg.svd(xy - xy.mean(0), full_matrices=False)[2][0]
        keep[sel] = abs(abs(np.degrees(np.arctan2(d[1], d[0])) % 180 - angle)) < 5
    return keep


def _pass(cloud, angle):
    """The points of the lines at ``angle`` degrees to x."""
    return cloud.points[_in_pass(cloud, angle)]


def test_the_turned_sheet_model_is_exact_on_ideal_sheets():
    """Observations made by the nominal light sheets of 45° lines, seen through the rig's
    camera: the turned fit gives the points back (the turn of world and camera is right)."""
    with connect(None, "step-block", 0, 4) as station:
        camera, H = station.rig.camera, station.rig.head.pivot_height_mm
    obs, truth = [], []
    for (a, b) in turned_lines(np.arange(-30, 31, 10.0), (-40, 40), CROSS_ANGLE_DEG):
        plane = light_plane(H, a, b)
        for z in (-10.0, 0.0, 10.0, 20.0):
            s = np.linspace(0, 1, 60)[:, None]
            xy = (1 - s) * a + s * b
            # the sheet at height z: move each ground point along the plane towards the pivot
            p = np.column_stack([xy * (H - z) / H, np.full(len(xy), z)])
            assert np.abs(p @ plane[:3] + plane[3]).max() < 1e-9
            uv = camera.project(p)
            obs.append(LineObservation(turned_offset(a, b, CROSS_ANGLE_DEG), z, *uv.T))
            truth.append(p)
    model = fit_turned_sheet(obs, camera, H, CROSS_ANGLE_DEG)
    back = TurnedSheetModel.from_dict(json.loads(json.dumps(model.to_dict())))
    got = np.vstack([back.points(camera, o.x_mm, o.u, o.v) for o in obs])
    assert np.abs(got - np.vstack(truth)).max() < 1e-3


def test_crossed_scan_lines_cover_the_region_at_their_angle():
    region = (-13.0, 13.0, -46.0, 46.0)
    lines = scan_lines(region, 0.5, CROSS_ANGLE_DEG)
    ends = np.array([p for ab in lines for p in ab])
    assert ends[:, 0].min() >= -13 - 1e-9 and ends[:, 0].max() <= 13 + 1e-9
    assert ends[:, 1].min() >= -46 - 1e-9 and ends[:, 1].max() <= 46 + 1e-9
    assert all(abs(line_angle(a, b) - 45.0) < 1e-9 for a, b in lines)
    offsets = np.array([turned_offset(a, b, 45.0) for a, b in lines])
    assert np.allclose(np.diff(offsets), 0.5)
    # every line but the corners' shortest: the region's width across, over the spacing
    assert len(lines) > (26 + 92) / np.sqrt(2) / 0.5 - 4


@pytest.mark.parametrize("method", ["plane", "height"])
def test_a_flat_plate_measured_by_both_passes_alike(crossed_cal, method):
    """The plate at 5 mm scanned crossed: each pass's heights as good as the other's
    (Method 1 keeps the nominal pivot's errors, about 0.2 mm on this rig, in both)."""
    cal = crossed_cal if method == "height" else None
    with connect(None, "step-block", 0, 4) as station:
        station.world.clear_table()
        station.devices.stage.move_z(5.0)
        cloud = scan_live(station, 2.0, (-20, 20, -30, 30), height_cal=cal, cross=True).cloud
    along, crossed = _pass(cloud, 90.0), _pass(cloud, 45.0)
    assert len(along) > 1000 and len(crossed) > 1000
    rms = [float(np.sqrt(np.mean((p[:, 2] - 5.0) ** 2))) for p in (along, crossed)]
    assert rms[1] < 2.0 * rms[0] + 0.02 and rms[1] < (0.1 if cal else 0.4), rms


def test_the_step_block_measured_by_both_passes_alike(crossed_cal):
    """The step block scanned crossed with the height calibration: each pass's points
    against the true surface (away from its walls)."""
    pose = (3.0, 2.0, 20.0)
    with simulated(sim_world("step-block", binning=4, pose=pose)) as station:
        cloud = scan_live(station, 1.0, height_cal=crossed_cal, cross=True).cloud
    scene = Scene([make_workpiece("table"), make_workpiece("step-block", x=pose[0],
                                                           y=pose[1], angle_deg=pose[2])])
    errs = []
    for p in (_pass(cloud, 90.0), _pass(cloud, 45.0)):
        z = []
        for dx, dy in ((0, 0), (0.5, 0), (-0.5, 0), (0, 0.5), (0, -0.5)):  # flat around it
            rays = np.column_stack([p[:, 0] + dx, p[:, 1] + dy, np.full(len(p), 80.0)])
            z.append(scene.cast(rays, np.tile([0.0, 0.0, -1.0], (len(p), 1))).points[:, 2])
        z = np.array(z)
        flat = np.ptp(z, axis=0) < 1e-6
        errs.append(float(np.median(np.abs(p[flat, 2] - z[0, flat]))))
    assert errs[1] < 0.1 and errs[1] < 2.5 * errs[0] + 0.01, errs


def test_the_calibration_file_holds_the_crossed_model(crossed_cal, tmp_path):
    assert crossed_cal.sheet_cross is not None
    assert crossed_cal.sheet_cross.line_angle_deg == CROSS_ANGLE_DEG
    r = crossed_cal.residuals
    assert r["sheet_cross_rms_mm"] < 2.5 * r["sheet_rms_mm"] and "sheet_cross_cv_rms_mm" in r
    raw = json.loads(crossed_cal.model_dump_json())
    raw["sheet_cross"]["line_angle_deg"] = 200.0
    (tmp_path / "bad.json").write_text(json.dumps(raw))
    with pytest.raises(Exception, match=r"sheet_cross.line_angle_deg: 200"):
        load_json_model(tmp_path / "bad.json", HeightCalibration)


def test_an_old_calibration_loads_and_refuses_a_crossed_scan_in_one_line(tmp_path):
    old = DATA / "height-cal-b2.json"
    cal = load_height_calibration(old)
    assert cal.sheet_cross is None
    with connect(None, "step-block", 0, 2) as station, \
            pytest.raises(MeasurementError) as e:
        scan_live(station, 1.0, height_cal=cal, cross=True)
    assert str(old) in str(e.value) and "record the height calibration with crossed lines" \
        in str(e.value) and "\n" not in str(e.value)
    res = CliRunner().invoke(app, ["scan", "--cross", "--height-cal", str(old), "--binning",
                                   "2", "-o", str(tmp_path / "c.ply")])
    assert res.exit_code == 1 and "no crossed lines" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "c.ply").exists()


def test_a_recorded_crossed_scan_replays_with_both_directions(tmp_path):
    """`sim record scan --cross` writes the crossed frames as ordinary line frames; the
    replay (Method 1) reconstructs them, each frame its own line index."""
    rec = tmp_path / "rec"
    res = CliRunner().invoke(app, ["sim", "record", "scan", "--cross", "--binning", "4",
                                   "--spacing", "2", "-o", str(rec)])
    assert res.exit_code == 0, res.output
    frames = json.loads((rec / "sequence.json").read_text())["frames"]
    angles = {round(line_angle(f["line"]["start"], f["line"]["end"])) for f in frames}
    assert angles == {45, 90}
    res = CliRunner().invoke(app, ["scan", "--replay", str(rec), "-o", str(tmp_path / "c.ply")])
    assert res.exit_code == 0, res.output
    from insitu.formats.pointcloud import read_ply
    cloud = read_ply(tmp_path / "c.ply")
    assert len(np.unique(cloud.attributes["line"])) > 0.8 * len(frames)
    assert len(_pass(cloud, 45.0)) > 1000


def test_a_part_square_to_the_lines_is_located_with_a_crossed_scan(crossed_cal):
    """The step block turned 90°: its long edges run along the lines along y, and the scan
    along y alone does not pin it down; with the crossed pass it is found where it lies
    (binning 4: within the coarse frame's precision and the rig's calibration offset), from
    edge samples of both passes."""
    from insitu.formats.pointcloud import PointCloud
    from insitu.locate.part import LocateRefused, LocateSettings
    from insitu.locate.reference import reference_from_mesh
    from insitu.services.locate import locate_cloud

    wp = make_workpiece("step-block")
    ref = reference_from_mesh(wp.vertices, wp.triangles, "step-block")
    truth, coarse = (8.0, -6.0, 90.0), LocateSettings(tolerance_mm=0.2,
                                                      turn_bound_deg=0.5)
    with simulated(sim_world("step-block", binning=4, pose=truth)) as station:
        cloud = scan_live(station, 0.5, height_cal=crossed_cal, cross=True).cloud
    # the lines along y alone: the scan without its crossed pass (which leaves them as they
    # are: test_the_crossed_pass_leaves_the_first_pass_as_it_was)
    along = _in_pass(cloud, 90.0)
    with pytest.raises(LocateRefused, match="not pinned down"):
        locate_cloud(ref, PointCloud(cloud.points[along], {k: v[along] for k, v in
                                                           cloud.attributes.items()},
                                     cloud.rig), coarse)
    table = cloud.points[:, 2] < 0.5
    u = edge_samples(cloud.points, cloud.attributes["line"], table).dirs
    angles = np.degrees(np.arctan2(u[:, 1], u[:, 0])) % 180
    assert (abs(angles - 90) < 5).sum() > 20 and (abs(angles - 45) < 5).sum() > 20
    best = locate_cloud(ref, cloud, coarse).best
    assert np.hypot(best.x_mm - truth[0], best.y_mm - truth[1]) < 0.2
    assert abs((best.angle_deg - truth[2] + 180) % 360 - 180) < 0.15


def test_the_crossed_pass_leaves_the_first_pass_as_it_was():
    """The check across neighbouring lines runs within each pass: the lines along y of a
    crossed scan keep exactly the points they keep without the crossed pass (checked with
    the crossed lines' points beside them, the first pass lost 200 more of its 10,000)."""
    from insitu.reconstruct.scan import ScanReconstructor
    from insitu.services.scan import plan_lines

    with simulated(sim_world("step-block", binning=4, pose=(3.0, 2.0, 20.0))) as station:
        rig, head, cam = station.rig, station.devices.head, station.devices.camera
        lines = plan_lines(station.default_region(), 0.5, cross=True)
        frames = []
        for a, b in lines:
            head.show_line(a, b)
            frames.append(cam.grab())
        head.off()
    along = [i for i, (a, b) in enumerate(lines) if a[0] == b[0]]
    clouds = []
    for use in (range(len(lines)), along):
        rec = ScanReconstructor(rig.camera, rig.head.pivot_height_mm,
                                z_range_mm=rig.head.z_range_mm)
        for i in use:
            rec.add(i, frames[i], *lines[i])
        clouds.append(rec.cloud(outlier_neighbours=0))
    first = clouds[0].attributes["line"] <= max(along)
    assert 0 < first.sum() < len(first)
    assert np.array_equal(clouds[0].points[first], clouds[1].points)


def test_new_recipes_scan_crossed_and_old_ones_do_not(tmp_path):
    """`recipe new` asks for the crossed pass (0.5 mm apart) unless --no-cross; a recipe file
    without the field scans along y only; `produce` with a crossed recipe and a height
    calibration without crossed lines stops before the first part, in one line."""
    from insitu.cli.recipe import read
    from insitu.formats.pointcloud import PointCloud, write_ply

    ref = tmp_path / "ref.ply"
    x, y = (a.ravel() for a in np.meshgrid(*[np.arange(-9, 9.01, 0.25)] * 2))
    z = np.where((abs(x) < 5) & (abs(y) < 3), 4.0, 0.0)           # a block on the table
    write_ply(ref, PointCloud(np.column_stack([x, y, z])))
    new = ["recipe", "new", str(ref), "--pattern", 'qr:"{serial}"', "--at", "0", "0"]
    for extra, cross in (([], True), (["--no-cross"], False)):
        out = tmp_path / f"r{cross}.json"
        assert CliRunner().invoke(app, new + extra + ["-o", str(out)]).exit_code == 0
        scan = json.loads(out.read_text())["scan"]
        assert scan["cross"] is cross and scan["cross_spacing_mm"] == 0.5
        assert read(out).scan.cross is cross
    res = CliRunner().invoke(app, ["recipe", "show", str(tmp_path / "rTrue.json")])
    flat = " ".join(re.sub("[│┃─┌┐└┘├┤┬┴┼]", " ", res.output).split())
    assert "then a crossed pass 0.5 mm apart" in flat
    raw = json.loads((tmp_path / "rTrue.json").read_text())
    del raw["scan"]["cross"], raw["scan"]["cross_spacing_mm"]
    (tmp_path / "old.json").write_text(json.dumps(raw))
    assert read(tmp_path / "old.json").scan.cross is False
    res = CliRunner().invoke(app, ["produce", str(tmp_path / "rTrue.json"), "--height-cal",
                                   str(DATA / "height-cal-b2.json"), "--binning", "2",
                                   "--no-wait"])
    assert res.exit_code == 1 and "record the height calibration with crossed lines" in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "rTrue.production.jsonl").exists()


def test_crossed_lines_leave_the_calibration_along_y_as_it_was(crossed_height_cal, crossed_cal,
                                                               tmp_path):
    """The crossed lines are recorded after the lines along y: the same station records the
    lines along y exactly as without them, so the model along y is the same."""
    frames = Sequence.open(crossed_height_cal / "hcal").frames
    along_y = [f for f in frames if f.line.start[0] == f.line.end[0]]
    heights = sorted({f.plate_z_mm for f in along_y})
    offsets = sorted({f.line.start[0] for f in along_y})
    with connect(None, "step-block", 0, 4) as station:
        record_height_calibration(station, tmp_path / "h", heights, offsets, cross=False)
    plain = calibrate_height(tmp_path / "h")
    assert plain.sheet_cross is None
    assert plain.sheet.coefficients_mm == crossed_cal.sheet.coefficients_mm
