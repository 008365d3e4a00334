"""A code marked on the simulated rig (binning 1) decodes from the rectified picture, its grade
follows the mark's quality, and ``insitu inspect`` reads a saved frame back."""

import dataclasses

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.marking import GalvoDriver, Placement, run_job
from insitu.services.inspect import raw_path, read_back_image, save_read_back
from insitu.services.mark import save_image
from insitu.services.plan import plan_mark
from insitu.services.station import simulated
from insitu.sim.controller import SimController
from insitu.sim.marks import RoomLightView, render_inspection
from insitu.sim.world import sim_world


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
