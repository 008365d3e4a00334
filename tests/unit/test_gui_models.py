"""The GUI's Qt-free parts: camera maths, undo history, project file, scene data, and the
command that starts without Qt."""

import json
import shutil

import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats.pointcloud import PointCloud
from insitu.formats.project import Project, RigChoice, ScanSettings, read_project, write_project
from insitu.marking import PROJECTIONS, Placement
from insitu.services.project import save_project
from insitu.ui.model import scene_data as sd
from insitu.ui.model.orbit_camera import OrbitCamera
from insitu.ui.model.session import PlacementHistory, Session


# -- camera -----------------------------------------------------------------------------
def test_project_and_ray_are_inverse():
    cam = OrbitCamera(centre=np.array([5.0, -3.0, 2.0]), distance_mm=200, azimuth_deg=-30,
                      elevation_deg=40)
    pts = np.array([[5.0, -3.0, 2.0], [20.0, 10.0, 0.0], [-15.0, 4.0, 12.0]])
    px = cam.project(pts, 800, 600)
    assert np.allclose(px[0], [400, 300], atol=1e-6)       # the centre is mid-screen
    for p, (x, y) in zip(pts, px):
        hit = cam.pick_plane(x, y, 800, 600, p[2])
        assert np.allclose(hit, p, atol=1e-6)


def test_top_view_has_x_right_and_y_up():
    cam = OrbitCamera()
    cam.set_view("top")
    px = cam.project(np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0]]), 640, 480)
    assert px[1, 0] > px[0, 0] + 5 and abs(px[1, 1] - px[0, 1]) < 1e-6
    assert px[2, 1] < px[0, 1] - 5 and abs(px[2, 0] - px[0, 0]) < 1e-6


def test_orbit_clamps_pan_moves_zoom_and_frame_fit():
    cam = OrbitCamera()
    cam.orbit(10, 500)
    assert cam.elevation_deg == 90.0
    cam.set_view("front")
    c0 = cam.centre.copy()
    cam.pan(100, 0, 600)                  # drag right: the scene follows, the centre goes −x
    assert cam.centre[0] < c0[0] and abs(cam.centre[2] - c0[2]) < 1e-9
    d = cam.distance_mm
    cam.zoom(0.5)
    assert cam.distance_mm == pytest.approx(d / 2)
    cam.set_view("iso")
    cam.frame((-10, -40, 0), (10, 40, 15))
    corners = np.array([[x, y, z] for x in (-10, 10) for y in (-40, 40) for z in (0, 15)])
    px = cam.project(corners, 800, 800)
    assert (px > 0).all() and (px < 800).all()


# -- undo -------------------------------------------------------------------------------
def test_history_undo_redo_and_merged_drag():
    h = PlacementHistory()
    a = Placement("text:\"A\"", (0.0, 0.0), 10.0)
    h.push((a,))
    key = object()
    for x in (1.0, 2.0, 3.0):                       # one drag = one undo step
        h.push((Placement(a.pattern, (x, 0.0), 10.0),), key)
    h.push((Placement(a.pattern, (3.0, 0.0), 12.0),))
    assert h.items[0].width_mm == 12.0
    h.undo()
    assert h.items[0].at_mm == (3.0, 0.0) and h.items[0].width_mm == 10.0
    h.undo()
    assert h.items == (a,)
    h.redo()
    assert h.items[0].at_mm == (3.0, 0.0)
    h.push(())                                      # a new change drops the redo branch
    assert not h.can_redo() and h.items == ()


def test_session_selection_and_combined_job():
    s = Session()
    s.add_placement(Placement("text:\"A\"", (0.0, 0.0), 10.0))
    s.add_placement(Placement("text:\"B\"", (5.0, 0.0), 10.0))
    assert s.selected == 1
    s.update_selected(rotate_deg=30.0)
    assert s.placements.items[1].rotate_deg == 30.0 and s.placements.items[0].rotate_deg == 0
    s.placements.undo()
    s.placements.undo()
    assert len(s.placements.items) == 1 and s.selected == 0
    assert s.job() is None                          # not planned yet


# -- project file -----------------------------------------------------------------------
def test_project_round_trip_with_relative_paths(tmp_path):
    (tmp_path / "calib").mkdir()
    (tmp_path / "calib" / "height.json").write_text("{}")
    (tmp_path / "logo.svg").write_text("<svg/>")
    (tmp_path / "part.cloud.ply").write_text("ply")
    pr = Project(RigChoice("step-block", 3, 4), tmp_path / "calib" / "height.json",
                 scan=ScanSettings((-10.0, 10.0, -40.0, 40.0), 0.25, 8.0, speed_mm_s=1500.0),
                 cloud=tmp_path / "part.cloud.ply",
                 placements=(Placement(str(tmp_path / "logo.svg"), (1.0, 2.0), 12.0, 15.0,
                                       "wrap", 0.1, 45.0, True),
                             Placement('text:"x"', (0.0, 0.0), 5.0)), selected=1)
    path = tmp_path / "p.insitu.json"
    write_project(path, pr)
    raw = json.loads(path.read_text())
    assert raw["format"] == "insitu-project/1" and raw["schema_version"] == 1
    assert raw["calibration"]["height"] == "calib/height.json"
    assert raw["placements"][0]["pattern"] == "logo.svg"
    back = read_project(path, Placement, PROJECTIONS)
    assert back.placements == pr.placements and back.scan == pr.scan
    assert back.rig == pr.rig and back.selected == 1
    assert back.cloud == tmp_path / "part.cloud.ply"
    moved = shutil.copytree(tmp_path, tmp_path.parent / f"{tmp_path.name}-moved")
    assert read_project(moved / "p.insitu.json", Placement, PROJECTIONS).cloud == moved / "part.cloud.ply"


@pytest.mark.parametrize("text, expect", [
    ("{not json", "not valid JSON"),
    ('{"format": "insitu-job/1", "paths": []}', "format: expected 'insitu-project/1'"),
    ('{"format": "insitu-project/1", "schema_version": 9}', "schema_version 9"),
    ('{"format": "insitu-project/1", "schema_version": 1, "placements": '
     '[{"pattern": "text:\\"a\\"", "at_mm": [0], "width_mm": 5}]}', "placements[0].at_mm"),
    ('{"format": "insitu-project/1", "schema_version": 1, "cloud": "gone.ply"}',
     "cloud: gone.ply not found"),
])
def test_bad_project_files_give_one_line(tmp_path, text, expect):
    path = tmp_path / "bad.insitu.json"
    path.write_text(text)
    with pytest.raises(FormatError) as e:
        read_project(path, Placement, PROJECTIONS)
    assert expect in str(e.value) and str(path) in str(e.value)
    assert "\n" not in str(e.value)


def test_save_writes_cloud_job_then_project(tmp_path):
    pts = np.random.default_rng(0).uniform(-5, 5, (200, 3))
    path = tmp_path / "s.insitu.json"
    written = save_project(path, Project(), PointCloud(pts), None)
    assert written.cloud == tmp_path / "s.cloud.ply" and written.cloud.exists()
    assert read_project(path, Placement, PROJECTIONS).cloud == written.cloud
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.cloud.ply", "s.insitu.json"]


# -- scene data -------------------------------------------------------------------------
def test_height_colours_run_blue_to_red():
    c = sd.height_colours(np.array([0.0, 7.5, 15.0, 99.0]), (0.0, 15.0))
    assert c.dtype == np.float32 and c.shape == (4, 3)
    assert c[0, 2] > c[0, 0] and c[2, 0] > c[2, 2]          # low blue, high red
    assert np.allclose(c[2], c[3])                          # clipped above the range


def test_handles_rotate_and_scale_drags():
    p = Placement('text:"AB"', (10.0, 5.0), 20.0, 0.0)
    h = sd.handles(p)
    assert np.allclose(h.centre, (10, 5))
    assert h.rotate[1] > h.corners[:, 1].max()              # above the top edge
    assert sd.rotate_to(p, (0.0, 5.0)) == pytest.approx(90.0)   # handle to the left: +90°
    assert sd.scale_to(p, 20.0, h.scale, h.centre + 2 * (h.scale - h.centre)) == pytest.approx(40.0)
    turned = sd.handles(Placement(p.pattern, p.at_mm, 20.0, 90.0))
    assert turned.rotate[0] < 10.0 - 1


def test_segments_pairs_vertices():
    v = sd.segments([np.array([[0, 0], [1, 0], [1, 1]])], z=2.0, closed=True)
    assert v.shape == (6, 3) and np.all(v[:, 2] == 2.0)
    assert np.allclose(v[-1], [0, 0, 2])


# -- the command ------------------------------------------------------------------------
def test_the_cli_starts_without_qt_and_offers_gui():
    import subprocess
    import sys

    code = ("import sys; from typer.testing import CliRunner; import insitu.cli.main as m; "
            "assert not [k for k in sys.modules if k.startswith(('PySide6', 'OpenGL'))]; "
            "r = CliRunner().invoke(m.app, ['gui', '--help']); print(r.output); "
            "r = CliRunner().invoke(m.app, ['gui', 'nowhere.insitu.json']); "
            "print(r.exit_code, type(r.exception).__name__, r.output)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert "Open the operator's application" in out.stdout
    assert ("1 SystemExit error: nowhere.insitu.json: project file not found"
            in " ".join(out.stdout.split()))


def test_the_gui_command_without_the_gui_packages_names_the_fix():
    import subprocess
    import sys

    code = ("import sys; sys.modules['PySide6'] = None; from typer.testing import CliRunner; "
            "import insitu.cli.main as m; r = CliRunner().invoke(m.app, ['gui']); "
            "print(r.exit_code, type(r.exception).__name__, r.output)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.split("\n")
    assert lines[0] == ("1 SystemExit error: the GUI needs PySide6 and PyOpenGL (PySide6 is not "
                        "installed): pip install 'insitu[gui]'"), out.stdout
    assert "Traceback" not in out.stdout and not "".join(lines[1:]).strip()


def test_a_code_hatch_follows_its_width_and_rotation_until_the_operator_sets_it():
    s = Session()
    qr = Placement('qr:"insitu"', (0.0, 0.0), 10.5)           # 21 modules of 0.5 mm
    spacing, angle = sd.code_hatch(qr)
    assert (spacing, angle) == pytest.approx((0.05, 0.0))
    s.add_placement(Placement(qr.pattern, qr.at_mm, qr.width_mm, hatch_mm=spacing))
    s.update_selected(width_mm=6.3)                            # 0.3 mm modules: 6 lines each
    assert s.current().hatch_mm == pytest.approx(0.05)
    s.update_selected(width_mm=7.35)                           # 0.35 mm: 7 lines of 0.05
    s.update_selected(width_mm=8.4, rotate_deg=30.0)           # 0.4 mm: 8 lines, along the rows
    assert (s.current().hatch_mm, s.current().hatch_angle_deg) == pytest.approx((0.05, 30.0))
    s.update_selected(width_mm=5.25)                           # 0.25 mm: 5 lines
    assert s.current().hatch_mm == pytest.approx(0.05)
    s.update_selected(width_mm=4.62)                           # 0.22 mm: 5 lines of 0.044
    assert s.current().hatch_mm == pytest.approx(0.044)
    s.update_selected(hatch_mm=0.03)                           # the operator's own hatch stays
    s.update_selected(width_mm=10.5)
    assert (s.current().hatch_mm, s.current().hatch_angle_deg) == (0.03, 30.0)
    s.add_placement(Placement('text:"A"', (0.0, 0.0), 5.0, hatch_mm=0.1))
    s.update_selected(width_mm=8.0)                            # not a code: untouched
    assert s.current().hatch_mm == 0.1 and sd.code_hatch(s.current()) is None


# -- unsaved changes, time left, the arming summary ---------------------------------------
def test_saved_state_names_what_changed_and_compares_the_cloud_by_identity():
    from insitu.ui.model.dirty import SavedState

    s = Session()
    cloud = PointCloud(np.zeros((3, 3)))
    state = lambda: {"placements": s.placements.items, "cloud": s.cloud}   # noqa: E731
    saved = SavedState(state)
    assert not saved.dirty()
    s.add_placement(Placement('text:"A"', (0.0, 0.0), 5.0))
    assert saved.changes() == ["placements"]
    s.set_cloud(cloud)
    assert saved.changes() == ["placements", "cloud"]
    saved.mark_clean()
    assert not saved.dirty()
    s.set_cloud(PointCloud(np.zeros((3, 3))))              # equal points, another cloud
    assert saved.changes() == ["cloud"]
    s.placements.undo()
    s.placements.redo()
    s.set_cloud(cloud)
    assert not saved.dirty()


def test_time_left_counts_down_without_jumps_and_rises_on_a_real_slowdown():
    from insitu.ui.model.time_left import TimeLeft

    # a short first path, then long ones: elapsed/done × left jumps (1.7 s → 13 s)
    path_s = np.r_[0.02, np.full(99, 0.13)]
    t, shown = TimeLeft(path_s), []
    elapsed = np.cumsum(path_s)
    for done in range(1, 100):
        shown.append(t.update(done, float(elapsed[done - 1])))
    assert shown[0] == pytest.approx(path_s[1:].sum(), rel=0.05)
    assert np.all(np.diff(shown) <= 1e-9)                   # monotone: never up
    assert shown[-1] == pytest.approx(0.13, abs=0.05)
    naive = [elapsed[d - 1] / d * (100 - d) for d in (1, 2)]
    assert naive[1] / naive[0] > 3                          # what elapsed / done × left does
    # the board slows to 3× the plan half-way: the estimate rises to the truth
    t = TimeLeft(np.full(100, 0.1))
    now = 0.0
    for done in range(1, 101):
        now += 0.1 if done <= 50 else 0.3
        left = t.update(done, now)
        if done == 50:
            before = left
        if done == 70:
            assert left > before and left == pytest.approx(30 * 0.3, rel=0.3)
    assert left == 0.0


def test_path_seconds_add_up_to_the_jobs_estimate():
    from insitu.marking import estimate_time, make_job, path_seconds

    job = make_job([np.array([[0, 0, 0], [10, 0, 0.0]]), np.array([[10, 5, 0], [0, 5, 0.0]]),
                    np.array([[0, 10, 0], [5, 10, 0.0], [5, 15, 0.0]])])
    assert path_seconds(job).sum() == pytest.approx(estimate_time(job).total_s)


def test_arm_rows_say_what_will_be_marked():
    from insitu.marking import make_job
    from insitu.ui.model.arming import arm_rows

    job = make_job([np.array([[0, 0, 1], [10, 0, 1.0]]), np.array([[10, 5, 2], [0, 5, 2.0]])])
    job = job.model_copy(update={"rig": {"workpiece": "arc", "seed": 0, "binning": 1}})
    rows = dict(arm_rows(job, ["logo.svg"], "sim camera · sim head", first_path=1,
                         choice={"resume": True, "cut_path": "skip"}))
    assert rows["patterns"] == "logo.svg" and rows["paths"] == "1 of 2"
    assert rows["marked length"].startswith("10 mm")
    assert rows["extent, mm"] == "x 0.00 … 10.00, y 0.00 … 5.00, z 1.00 … 2.00"
    assert "workpiece arc" in rows["planned on"] and rows["run"] == "resume, cut path: skip"
    assert rows["laser"].startswith("30 %, 20 kHz")


def test_a_calibrations_verdict_names_its_figures_against_their_limits():
    from insitu.ui.model.calibration_verdict import verdict

    res = {"sheet_rms_mm": 0.021, "sheet_cv_rms_mm": 0.023, "sheet_points": 117600.0}
    level, line, rows = verdict("height", res)
    assert level == "pass" and line.startswith("height calibration: pass — ")
    assert rows[0].name == "height error on planes left out of the fit, RMS"
    assert rows[0].value == "0.023 mm" and rows[0].level == "pass"
    assert ("sheet points", "117,600") in [(r.name, r.value) for r in rows]
    assert verdict("height", {**res, "sheet_cv_rms_mm": 0.07})[0] == "check"
    level, line, _ = verdict("height", {**res, "sheet_rms_mm": 0.4})
    assert level == "fail" and "record it again" in line and "0.4 mm" in line
    assert verdict("camera", {"rms_px": float("nan")})[0] == "fail"
    assert verdict("field", {"points": 400.0})[0] == "check"          # nothing to judge by


@pytest.mark.parametrize("view", ["top", "front", "iso"])
def test_framing_leaves_the_colour_bars_band_free(view):
    cam = OrbitCamera()
    cam.set_view(view)
    lo, hi = (-40.0, -60.0, 0.0), (40.0, 60.0, 12.0)
    cam.frame(lo, hi, aspect=1.5, reserve=0.25)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    px = cam.project(corners, 600, 400)
    assert np.isfinite(px).all()
    assert px[:, 0].min() > 0 and px[:, 0].max() < 0.75 * 600     # left of the band
    assert px[:, 1].min() > 0 and px[:, 1].max() < 400


def _luminance(rgb) -> float:
    c = np.asarray(rgb, float)
    c = np.where(c <= 0.03928, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return float(c @ [0.2126, 0.7152, 0.0722])


def _contrast(a, b) -> float:
    la, lb = sorted((_luminance(a), _luminance(b)))
    return (lb + 0.05) / (la + 0.05)


def test_every_default_pen_stands_out_from_the_height_colours_under_it():
    from insitu.formats.pens import DEFAULT_PENS

    surface = sd.height_colours(np.linspace(0, 1, 101), (0.0, 1.0))
    for pen in DEFAULT_PENS.pens:
        rgb = [int(pen.colour[i:i + 2], 16) / 255 for i in (1, 3, 5)]
        worst = min(_contrast(rgb, c * sd.SHADE_UNDER_PENS) for c in surface)
        assert worst >= 2.0, (pen.name, worst)
    fine = next(p for p in DEFAULT_PENS.pens if p.name == "fine")
    rgb = [int(fine.colour[i:i + 2], 16) / 255 for i in (1, 3, 5)]
    assert min(_contrast(rgb, c) for c in surface) < 1.3      # undimmed: lost in the map
