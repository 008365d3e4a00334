"""Reading marks back: the camera's image rectified onto the surface (planar and wrap) puts a
known pattern where it is, the measured surface hides what the camera cannot see, a code
marked on the simulated rig decodes from the rectified picture, and its grade follows the
mark's quality."""

import dataclasses

import numpy as np
import pytest
from scipy import ndimage
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.geometry.camera import CameraModel
from insitu.marking import GalvoDriver, Placement, run_job
from insitu.marking.project import Projection
from insitu.marking.readback import find_offset
from insitu.marking.rectify import mark_frame, occluded, rectify, surface_points
from insitu.marking.surface import Surface
from insitu.patterns.model import Pattern
from insitu.services.inspect import raw_path, read_back_image, save_read_back
from insitu.services.mark import save_image
from insitu.services.plan import plan_mark
from insitu.services.station import simulated
from insitu.sim.devices import SimController
from insitu.sim.marks import RoomLightView, render_inspection
from insitu.sim.world import sim_world

R_MM = 12.0                    # the test cylinder's radius
DOTS = np.array([[u, v] for u in (-4.0, -1.5, 1.0, 3.5) for v in (-3.0, 0.5, 3.0)])


def _camera() -> CameraModel:
    """Oblique, the pattern far off its axis, so the lens distortion moves it ~8 px."""
    K = np.array([[900.0, 0, 400], [0, 900.0, 300], [0, 0, 1]])
    return CameraModel.look_at(800, 600, K, np.array([-0.3, 0.08, 0, 0, 0]),
                               np.array([-60.0, 10.0, 90.0]), np.array([30.0, -20.0, 3.0]),
                               np.array([0.0, -1.0, 0.0]))


def _surface_uv(kind: str, p: np.ndarray) -> np.ndarray:
    """World points (N, 3) on the test surface → pattern-plane (u, v) mm (u along x)."""
    if kind == "planar":
        return p[:, :2]
    return np.column_stack([R_MM * np.arcsin(np.clip(p[:, 0] / R_MM, -1, 1)), p[:, 1]])


def _hit(kind: str, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Rays (origin, (N, 3) directions) meet the test surface: (N, 3) mm."""
    if kind == "planar":                  # z = 3 + 0.15 x
        t = (3 + 0.15 * o[0] - o[2]) / (d[:, 2] - 0.15 * d[:, 0])
        return o + t[:, None] * d
    c = np.array([0.0, 0.0, 3.0 - R_MM])  # cylinder about y through c
    oc = o - c
    a = d[:, 0] ** 2 + d[:, 2] ** 2
    b = 2 * (oc[0] * d[:, 0] + oc[2] * d[:, 2])
    cc = oc[0] ** 2 + oc[2] ** 2 - R_MM ** 2
    disc = b * b - 4 * a * cc
    t = (-b - np.sqrt(np.where(disc >= 0, disc, np.nan))) / (2 * a)     # NaN: a miss
    return o + t[:, None] * d


def _z(kind: str, xy: np.ndarray) -> np.ndarray:
    if kind == "planar":
        return 3 + 0.15 * xy[:, 0]
    return 3.0 - R_MM + np.sqrt(R_MM ** 2 - xy[:, 0] ** 2)


@pytest.mark.parametrize("kind", ["planar", "wrap"])
def test_rectified_picture_puts_a_known_pattern_where_it_is(kind):
    cam = _camera()
    uu, vv = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    o, d = cam.rays(np.column_stack([uu.ravel(), vv.ravel()]))
    uv = _surface_uv(kind, _hit(kind, o, d))
    r2 = ((uv[:, None, :] - DOTS[None]) ** 2).sum(-1).min(1)
    image = (200 - 150 * np.exp(-r2 / (2 * 0.25 ** 2))).reshape(cam.height, cam.width)
    g = np.meshgrid(np.arange(-9, 9.01, 0.1), np.arange(-9, 9.01, 0.1))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    surf = Surface(np.column_stack([xy, _z(kind, xy)]))
    square = np.array([[-6.0, -5.0], [6.0, -5.0], [6.0, 5.0], [-6.0, 5.0]])
    pattern = Pattern(contours=(square,), frame=square)
    frame = mark_frame(pattern, 0.5, 0.04)
    proj = Projection([], kind, 0.1, 0.4, np.zeros(0), np.zeros(0),
                      direction_deg=0.0 if kind == "wrap" else None,
                      anchor=(0.0, 0.0) if kind == "wrap" else None)
    points = surface_points(frame, surf, proj)
    pic = rectify(image, cam, points, surf.points, 0.1)
    assert np.isfinite(pic).mean() > 0.99
    dark = np.nan_to_num(200 - pic)
    labels, n = ndimage.label(dark > 40)
    assert n == len(DOTS)
    found = np.array(ndimage.center_of_mass(dark, labels, range(1, n + 1)))[:, ::-1]
    found_uv = np.column_stack([found[:, 0] * frame.px_mm,
                                (frame.shape[0] - found[:, 1]) * frame.px_mm])
    want = frame.to_uv(DOTS)
    err = np.linalg.norm(found_uv[:, None] - want[None], axis=-1).min(1) / frame.px_mm
    assert err.max() < 0.25, err                 # a quarter of a picture pixel (10 µm)


def test_what_the_surface_hides_from_the_camera_is_masked():
    g = np.meshgrid(np.arange(-10, 10.01, 0.1), np.arange(-5, 5.01, 0.1))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    cloud = np.column_stack([xy, np.where(xy[:, 0] < 0, 10.0, 0.0)])   # a wall at x = 0
    camera = np.array([-150.0, 0.0, 327.0])       # up and to the −x side, as the sim's
    pts = np.array([[2.0, 0, 0], [4.0, 1, 0], [6.0, 0, 0], [-3.0, 0, 10.0], [np.nan] * 3])
    hidden = occluded(pts, camera, cloud, 0.1)
    assert hidden.tolist() == [True, True, False, False, False]   # behind it: x < 4.6 mm


def test_find_offset_locates_a_shifted_mark_of_either_polarity():
    plan = np.full((120, 140), 255, np.uint8)
    plan[30:90, 40:100:8] = 0
    plan[50:54, 30:110] = 0
    shifted = ndimage.shift(plan.astype(np.float32), (-2.3, 3.6), order=1, mode="nearest")
    dx, dy, c = find_offset(shifted, plan, 10, 6.0)
    assert (dx, dy) == pytest.approx((3.6, -2.3), abs=0.15) and c > 0
    dx, dy, c = find_offset(255 - shifted, plan, 10, 6.0)          # light marks on dark
    assert (dx, dy) == pytest.approx((3.6, -2.3), abs=0.15) and c < 0


# ------------------------------------------------------------- on the simulated rig
@pytest.fixture(scope="module")
def marked():
    """A 0.4 mm QR marked on the step block's 3 mm top (the head's field correction
    perfect), its cloud (the true top, 0.1 mm grid), plan, burns and a renderer."""
    world = sim_world("step-block", seed=0, binning=1)
    station = simulated(world)
    g = np.meshgrid(np.arange(-10, 10.01, 0.1), np.arange(-40, -20.01, 0.1))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    z = world.parts[0].height(xy[:, 0], xy[:, 1])
    cloud = PointCloud(np.column_stack([xy, z + np.random.default_rng(0).normal(0, 0.01,
                                                                             len(z))]))
    plan = plan_mark(cloud, Placement('qr:"SN 0042";module=0.4', (0.5, -30.0), None, 25.0),
                     station.driver)
    sc = SimController(world)
    run_job(plan.job, GalvoDriver.from_config(world.rig.operator.head,
                                              world.rig.ideal_correction()), sc)
    view = RoomLightView(world.rig, sc.scene)           # one ray cast for every frame

    def frame(burns=None, contrast=0.75):
        return render_inspection(world.rig, sc.scene, sc.burns if burns is None else burns,
                                 seed=3, contrast=contrast, view=view)
    return station, cloud, plan, sc.burns, frame


def test_a_code_marked_on_the_sim_reads_back_from_the_rectified_picture(marked, tmp_path):
    station, cloud, plan, _, frame = marked
    result = read_back_image(frame(), station.rig.camera, cloud, [plan])
    r = result.readings[0]
    assert r.decoded == "SN 0042" and r.ok and result.ok
    # marked where planned (perfect field correction): what the camera sees is the operator's
    # camera calibration's error, ~0.1 mm
    assert np.hypot(*r.offset_mm) < 0.15
    assert r.grades.overall >= 2 and r.grades.decode == 4 and r.seen > 0.95
    out = tmp_path / "marked.png"
    raw = save_read_back(out, result)
    assert raw == raw_path(out) == tmp_path / "marked.raw.png" and raw.exists()
    pic = result.picture
    plan_ink = (pic[..., 2] > 200) & (pic[..., 1] > 100) & (pic[..., 1] < 180) & (pic[..., 0] < 60)
    assert plan_ink.sum() > 500                   # the plan's outlines drawn over the mark


def test_the_grade_follows_the_marks_quality(marked):
    station, cloud, plan, burns, frame = marked
    good = read_back_image(frame(), station.rig.camera, cloud, [plan]).readings[0].grades
    faint = read_back_image(frame(contrast=0.12), station.rig.camera, cloud,
                            [plan]).readings[0].grades
    assert faint.cell_contrast < 0.5 * good.cell_contrast
    assert faint.cell_contrast_grade < good.cell_contrast_grade and faint.overall < good.overall
    # a scratch through the marks: every burn sample in a band across the symbol lost
    c = np.array(plan.pattern.centre)

    def scratched(b):
        gone = np.abs(b.points[:, 1] - c[1] - 1.0) < 0.5
        return dataclasses.replace(b, points=np.where(gone[:, None], np.nan, b.points))
    damaged = read_back_image(frame([scratched(b) for b in burns]), station.rig.camera, cloud,
                              [plan]).readings[0].grades
    # the scratched modules are clearly light: their modulation is fine, their margin (the
    # wrong side of the threshold) not; the finder patterns it crosses are damaged
    assert damaged.reflectance_margin < min(good.reflectance_margin, damaged.cell_modulation)
    assert damaged.fixed_errors > good.fixed_errors and damaged.fixed_pattern < 4
    assert damaged.overall < good.overall


def test_inspect_reads_a_saved_frame_back(marked, tmp_path):
    station, cloud, plan, _, frame = marked
    write_ply(tmp_path / "c.ply", cloud)
    save_image(tmp_path / "f.png", frame())
    res = CliRunner().invoke(app, ["inspect", str(tmp_path / "f.png"), "--cloud",
                                   str(tmp_path / "c.ply"), "--pattern", 'qr:"SN 0042";module=0.4',
                                   "--at", "0.5", "-30", "--rotate", "25", "-o",
                                   str(tmp_path / "p.png")])
    assert res.exit_code == 0, res.output
    assert "SN 0042" in res.output and "yes" in res.output and (tmp_path / "p.png").exists()
    res = CliRunner().invoke(app, ["inspect", str(tmp_path / "f.png"), "--cloud",
                                   str(tmp_path / "c.ply"), "--pattern", 'qr:"SN 0043";module=0.4',
                                   "--at", "0.5", "-30", "--rotate", "25", "-o",
                                   str(tmp_path / "q.png")])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit)
    save_image(tmp_path / "small.png", np.zeros((100, 120), np.uint8))   # not this camera's
    res = CliRunner().invoke(app, ["inspect", str(tmp_path / "small.png"), "--cloud",
                                   str(tmp_path / "c.ply"), "--pattern", 'qr:"SN 0042"',
                                   "--at", "0.5", "-30", "-o", str(tmp_path / "r.png")])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit)
    assert "small.png: image is 120x100 pixels, the camera is 2448x2048" in res.output
    assert not (tmp_path / "r.png").exists()


def test_inspect_reads_a_mark_with_fields_back_as_its_job_rendered_it(marked, tmp_path):
    """A pattern with {serial}: the text comes from the job it was marked with (serial 42 is
    what the frame shows, 43 is not); without --job it is one line naming the option."""
    station, cloud, plan, _, frame = marked
    write_ply(tmp_path / "c.ply", cloud)
    save_image(tmp_path / "f.png", frame())
    spec = 'qr:"SN {serial:04d}";module=0.4'
    place = ["--pattern", spec, "--at", "0.5", "-30", "--rotate", "25"]
    for serial, code in ((42, 0), (43, 1)):
        job = tmp_path / f"job{serial}.json"
        res = CliRunner().invoke(app, ["mark", "--cloud", str(tmp_path / "c.ply"), *place,
                                       "-o", str(job), "--counter",
                                       str(tmp_path / f"{serial}.counter.json"),
                                       "--serial-start", str(serial)])
        assert res.exit_code == 0, res.output
        res = CliRunner().invoke(app, ["inspect", str(tmp_path / "f.png"), "--cloud",
                                       str(tmp_path / "c.ply"), *place, "--job", str(job),
                                       "-o", str(tmp_path / f"p{serial}.png")])
        assert res.exit_code == code, res.output
        assert f"SN {serial:04d}" in res.output
    res = CliRunner().invoke(app, ["inspect", str(tmp_path / "f.png"), "--cloud",
                                   str(tmp_path / "c.ply"), *place, "-o", str(tmp_path / "x.png")])
    assert res.exit_code == 1 and res.output.startswith("error: --pattern ") \
        and "has fields: name the job it was marked with" in res.output \
        and not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("spec", ['qr:"SN 0042"', 'microqr:"SN42"', 'datamatrix:"SN 0042"',
                                  'code128:"SN 0042"'])
def test_a_perfect_mark_grades_a_and_a_blurred_faint_one_lower(spec):
    from insitu.marking.readback import _grade, decode_picture
    from insitu.marking.verify import render

    placement = Placement(f"{spec};module=0.3", (1.0, -2.0), None, 30.0)
    pattern = placement.placed()
    module = 0.3
    frame = mark_frame(pattern, 2 * module, module / 8)
    drawn = render(placement.polylines(pattern), frame.origin, frame.axes, frame.size_mm,
                   placement.beam_mm, frame.px_mm).astype(np.float32)
    symbology = spec.split(":")[0]
    assert decode_picture(drawn, symbology, 8.0) == pattern.code.text
    perfect = _grade(drawn, frame, pattern, module, (0.0, 0.0), True)
    assert perfect.overall == 4, perfect.summary()
    assert (perfect.axial_grade is None) == (symbology == "code128")
    poor = ndimage.gaussian_filter(drawn, 4.0) * 0.15 + 180
    rng = np.random.default_rng(1)
    poor = poor + rng.normal(0, 3, poor.shape).astype(np.float32)
    low = _grade(poor, frame, pattern, module, (0.0, 0.0), True)
    assert low.overall < 4 and low.cell_contrast < 0.2 * perfect.cell_contrast, low.summary()
