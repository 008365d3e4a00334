"""The scan-head driver: command stream, laser safety, resume, and marking on the sim rig."""

from dataclasses import replace

import numpy as np
import pytest

from golden import GOLDEN, HEAD, mark_small_job, small_job
from insitu.devices.galvo import (
    Controller,
    RecordingController,
    focus_points,
    joint_from_targets,
    nominal_commands,
)
from insitu.errors import DeviceError, FormatError, SafetyError
from insitu.geometry.beams import TwoMirrorHead
from insitu.geometry.distortion import NoDistortion
from insitu.marking import (
    GalvoDriver,
    Limits,
    estimate_time,
    make_job,
    progress_path_for,
    read_progress,
    run_job,
    run_preview,
    write_job,
)
from insitu.sim.controller import SimController
from insitu.sim.marks import find_marks, mark_darkness, render_inspection
from insitu.sim.rig import default_rig
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld


def many_paths_job(n=6):
    return make_job([np.array([[x, -3.0, 0.5], [x, 3.0, 0.5], [x + 0.5, 3.0, 0.5]])
                     for x in np.linspace(-10, 10, n)])


def _jump(commands):
    """A path's identity in a command list: where it jumps to."""
    return next(tuple(c.args) for c in commands if c.op == "jump_abs_3d")


class FaultyController(RecordingController):
    """Raises DeviceError at the ``fail_at``-th command (0-based), after executing those
    before it; counts the paths it completed (a list executed to its end)."""

    def __init__(self, fail_at: int | None = None, exc=DeviceError):
        super().__init__()
        self.fail_at, self.exc, self.completed_lists = fail_at, exc, []

    def execute(self, commands):
        for c in commands:
            if self.fail_at is not None and len(self.commands) == self.fail_at:
                raise self.exc("injected fault: galvo position error")
            super().execute([c])
        self.completed_lists.append(_jump(commands))


def test_recording_controller_is_a_controller():
    assert isinstance(RecordingController(), Controller)


def test_golden_listing_of_a_small_job():
    """Compares only: scripts/regen-golden.py rewrites the file after a reviewed change."""
    result, rc = mark_small_job()
    assert result.state == "done" and result.completed == 2
    assert rc.listing() == GOLDEN.read_text()
    assert rc.off_calls == 1 and not rc.laser_is_on


def test_laser_on_only_while_marking():
    rc = RecordingController()
    run_job(many_paths_job(), GalvoDriver(HEAD), rc)
    on = False
    for c in rc.commands:
        if c.op == "laser_on":
            assert not on
            on = True
        elif c.op == "laser_off":
            on = False
        elif c.op == "jump_abs_3d":
            assert not on, "jump with the laser on"
    assert not on
    ops = [c.op for c in rc.commands]
    assert ops.count("laser_on") == ops.count("laser_off") == 6
    # settings are sent once, not per path
    assert ops.count("set_power") == ops.count("set_mark_speed") == 1


def test_commands_are_the_inverse_kinematics():
    pts = np.array([[12.0, -30.0, 4.0], [-50.0, 20.0, -7.0]])
    j = joint_from_targets(HEAD, pts)
    ax, ay, _ = HEAD.inverse(pts[:, 0], pts[:, 1], pts[:, 2])
    np.testing.assert_allclose(j[:, :2], np.degrees(np.column_stack([ax, ay])))
    np.testing.assert_allclose(j[:, 2], HEAD.focus_shift(pts[:, 0], pts[:, 1], pts[:, 2]))
    np.testing.assert_allclose(focus_points(HEAD, j), pts, atol=1e-9)


def test_field_correction_is_applied_to_the_z0_command():
    shift = np.array([0.3, -0.2])
    drv = GalvoDriver(HEAD, correction=lambda q: q + shift)
    pts = np.array([[20.0, 10.0, 0.0], [20.0, 10.0, 5.0]])
    j = drv.joints(pts)
    q0 = nominal_commands(HEAD, joint_from_targets(HEAD, pts))
    np.testing.assert_allclose(nominal_commands(HEAD, j), q0 + shift, atol=1e-9)
    # the focus follows the corrected beam to the target's height
    np.testing.assert_allclose(focus_points(HEAD, j)[:, 2], pts[:, 2], atol=1e-9)


def test_laser_off_after_a_fault_mid_job(tmp_path):
    job = many_paths_job()
    f = tmp_path / "job.json"
    write_job(f, job)
    n_first_paths = sum(len(c) for c in GalvoDriver(HEAD).compile(job)[:2])
    fc = FaultyController(fail_at=n_first_paths + 9)          # inside path 2, laser on
    with pytest.raises(DeviceError, match="injected fault"):
        run_job(job, GalvoDriver(HEAD), fc, progress_path_for(f))
    assert any(c.op == "laser_on" for c in fc.commands[n_first_paths:])
    assert not fc.laser_is_on and fc.off_calls == 1
    rec = read_progress(progress_path_for(f))
    assert rec["state"] == "interrupted" and rec["completed"] == 2
    assert rec["last_completed_path"] == 1 and "injected fault" in rec["error"]
    assert rec["job_sha256"] == job.digest() and rec["paths_total"] == 6


def test_laser_off_after_ctrl_c():
    fc = FaultyController(fail_at=12, exc=KeyboardInterrupt)
    with pytest.raises(KeyboardInterrupt):
        run_job(many_paths_job(), GalvoDriver(HEAD), fc)
    assert not fc.laser_is_on and fc.off_calls == 1


def test_resume_completes_every_path_exactly_once(tmp_path):
    job = many_paths_job(8)
    prog = progress_path_for(tmp_path / "job.json")
    lists = GalvoDriver(HEAD).compile(job)
    done = []
    for fail_at in (sum(map(len, lists[:3])) + 5, 17):      # two faults, then a clean run
        fc = FaultyController(fail_at=fail_at)
        with pytest.raises(DeviceError):       # the path a fault cuts is marked again whole
            run_job(job, GalvoDriver(HEAD), fc, prog, resume=True, cut_path="remark")
        done += fc.completed_lists
        assert not fc.laser_is_on
    fc = FaultyController()
    result = run_job(job, GalvoDriver(HEAD), fc, prog, resume=True, cut_path="remark")
    done += fc.completed_lists
    assert result.state == "done" and result.completed == 8
    firsts = [_jump(lst) for lst in lists]
    assert sorted(done) == sorted(firsts)                   # every path once, none twice
    assert read_progress(prog)["state"] == "done"
    again = FaultyController()
    assert run_job(job, GalvoDriver(HEAD), again, prog, resume=True).state == "done"
    assert again.commands == []                            # nothing marked twice


def test_resume_refuses_another_jobs_progress(tmp_path):
    prog = tmp_path / "job.progress.json"
    run_job(many_paths_job(), GalvoDriver(HEAD), RecordingController(), prog)
    with pytest.raises(FormatError, match="job_sha256: records another job"):
        run_job(small_job(), GalvoDriver(HEAD), RecordingController(), prog, resume=True)


def test_unsafe_job_is_refused_before_the_first_command():
    job = make_job([np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]]),
                    np.array([[0.0, 0.0, 30.0], [1.0, 0.0, 30.0]])])
    rc = RecordingController()
    with pytest.raises(SafetyError, match="outside the focus range"):
        run_job(job, GalvoDriver(HEAD), rc)
    assert rc.commands == []
    with pytest.raises(SafetyError, match="after the field correction"):
        GalvoDriver(HEAD, Limits((200.0, 200.0)), correction=lambda q: q * 1.1).check(
            make_job([np.array([[95.0, 0.0, 0.0], [96.0, 0.0, 0.0]])]))


def test_pilot_preview_never_fires_the_laser():
    job = many_paths_job()
    rc = RecordingController()
    run_preview(job, GalvoDriver(HEAD), rc, outline="hull", repeat=2)
    ops = [c.op for c in rc.commands]
    assert "laser_on" not in ops and ops.count("pilot_on") == 2 == ops.count("pilot_off")
    assert not rc.pilot_is_on and rc.off_calls == 1
    marks = focus_points(HEAD, np.array([c.args for c in rc.commands if c.op == "mark_abs_3d"]))
    pts = np.vstack([p.points for p in job.paths])
    assert marks[:, 0].min() == pytest.approx(pts[:, 0].min(), abs=1e-6)
    assert marks[:, 1].max() == pytest.approx(pts[:, 1].max(), abs=1e-6)
    rc2 = RecordingController()
    run_preview(job, GalvoDriver(HEAD), rc2, outline="bbox")
    assert sum(c.op == "mark_abs_3d" for c in rc2.commands) == 4


# --------------------------------------------------------------------------- sim rig
def plate_world(rig, z=0.0):
    parts = [make_workpiece("plate", top_z=z, width=150, length=150)] if z else []
    return SimWorld(rig, parts=parts)


def landing_error(ctrl, targets):
    """Distances (per burn point) to the target polyline in x-y, and the burn points."""
    from shapely.geometry import LineString, Point
    pts = np.vstack([b.points for b in ctrl.burns])
    line = LineString(targets[:, :2])
    return np.array([line.distance(Point(p[:2])) for p in pts[::7]]), pts


@pytest.fixture(scope="module")
def rig():
    return default_rig(seed=3, binning=4)


def test_sim_marks_land_on_target_without_distortion(rig):
    ideal = replace(rig, head=TwoMirrorHead(rig.operator.head.mirror_distance_mm,
                                            rig.operator.head.mirror_separation_mm),
                    distortion=NoDistortion())
    world = plate_world(ideal, z=6.0)
    targets = np.array([[-60.0, -40.0, 6.0], [55.0, 35.0, 6.0], [55.0, -50.0, 6.0]])
    job = make_job([targets])
    sc = SimController(world)
    run_job(job, GalvoDriver.from_config(ideal.operator.head), sc)
    err, pts = landing_error(sc, targets)
    assert err.max() < 0.02
    np.testing.assert_allclose(pts[0], targets[0], atol=0.02)
    np.testing.assert_allclose(pts[-1], targets[-1], atol=0.02)
    assert np.allclose(pts[:, 2], 6.0, atol=1e-3)
    assert not sc.laser_is_on and len(sc.burns) == 1
    assert sc.elapsed_s == pytest.approx(estimate_time(job).total_s, rel=1e-9)
    w = sc.burns[0].widths
    assert np.all(w >= 2 * rig.optics.beam_waist_mm - 1e-9) and np.all(w < 0.31)


def test_sim_marks_are_off_by_the_distortion_when_uncorrected(rig):
    world = plate_world(rig)                                # marking on the table, z = 0
    targets = np.array([[-70.0, 60.0, 0.0], [70.0, 60.0, 0.0]])
    sc = SimController(world)
    run_job(make_job([targets]), GalvoDriver.from_config(rig.operator.head), sc)
    pts = np.vstack([b.points for b in sc.burns])
    offset = pts[[0, -1], :2] - targets[:, :2]
    assert np.linalg.norm(offset, axis=1).min() > 0.1       # visibly off target …
    np.testing.assert_allclose(offset, rig.distortion(targets[:, :2]), atol=0.02)  # … by this

    def inverse_distortion(q):                              # a perfect field correction
        k = q.copy()
        for _ in range(30):
            k = q - rig.distortion(k)
        return k
    sc2 = SimController(plate_world(rig))
    run_job(make_job([targets]), GalvoDriver.from_config(rig.operator.head, inverse_distortion), sc2)
    pts2 = np.vstack([b.points for b in sc2.burns])
    np.testing.assert_allclose(pts2[[0, -1], :2], targets[:, :2], atol=0.02)


def test_inspection_image_shows_the_marks(rig):
    world = plate_world(rig, z=4.0)
    sq = np.array([[-15.0, -15], [15, -15], [15, 15], [-15, 15], [-15, -15]])
    targets = np.column_stack([sq, np.full(5, 4.0)])
    sc = SimController(world)
    run_job(make_job([targets]), GalvoDriver.from_config(rig.operator.head), sc)
    clean = render_inspection(rig, sc.scene, [], ideal=True)
    marked = render_inspection(rig, sc.scene, sc.burns, ideal=True)
    uv = rig.camera.project(np.array([[0.0, -15.0, 4.0], [0.0, 0.0, 4.0]]))
    (u0, v0), (u1, v1) = np.rint(uv).astype(int)
    assert marked[v0, u0] < 0.6 * clean[v0, u0]             # on the mark: dark
    assert marked[v1, u1] == pytest.approx(clean[v1, u1])    # inside the square: untouched
    noisy = render_inspection(rig, sc.scene, sc.burns, seed=1)
    assert noisy.dtype == np.uint8
    xy, w = find_marks(noisy, rig.operator.camera, 4.0, kernel_px=9)
    assert len(xy) > 100
    d_side = np.min(np.abs(np.column_stack([np.abs(xy[:, 0]) - 15, np.abs(xy[:, 1]) - 15])), 1)
    assert np.median(d_side) < 0.4                          # found on the square's sides


def test_burns_stay_on_the_world_and_the_inspection_camera_sees_them(rig):
    from insitu.sim.devices import SimInspectionCamera
    world = plate_world(rig, z=4.0)
    cam = SimInspectionCamera(world)
    before = cam.grab().astype(float)
    for y in (-5.0, 5.0):                                   # two jobs, two controllers
        targets = np.array([[-10.0, y, 4.0], [10.0, y, 4.0]])
        run_job(make_job([targets]), GalvoDriver.from_config(rig.operator.head), SimController(world))
    assert len(world.burns) == 2
    after = cam.grab().astype(float)
    u, v = np.rint(rig.camera.project(np.array([[0.0, 5.0, 4.0]]))[0]).astype(int)
    assert after[v - 1:v + 2, u - 1:u + 2].min() < 0.6 * before[v - 1:v + 2, u - 1:u + 2].mean()


def test_sim_burns_each_pass_and_a_wobble_widens_the_burn(rig):
    from insitu.formats.pens import Pen, Wobble
    from insitu.marking import with_pen

    targets = np.array([[-10.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    plain = SimController(plate_world(rig))
    run_job(make_job([targets]), GalvoDriver.from_config(rig.operator.head), plain)
    pen = Pen(name="p", passes=2, wobble=Wobble(amplitude_mm=0.2, frequency_hz=1000.0))
    job = with_pen(make_job([targets]), pen)
    sc = SimController(plate_world(rig))
    run_job(job, GalvoDriver.from_config(rig.operator.head), sc)
    assert len(plain.burns) == 1 and len(sc.burns) == 1 and sc.burns[0].passes == 2
    np.testing.assert_allclose(np.nanmean(sc.burns[0].widths),
                               np.nanmean(plain.burns[0].widths) + 0.4, rtol=1e-6)
    on = sc.burns[0].points[len(sc.burns[0].points) // 2][None]       # the second pass darkens
    assert mark_darkness(on, plain.burns)[0] == pytest.approx(0.75, abs=0.01)
    assert mark_darkness(on, sc.burns)[0] == pytest.approx(1 - 0.25 ** 2, abs=0.01)
    assert sc.elapsed_s == pytest.approx(estimate_time(job).total_s, rel=1e-9)
    beside = make_job([targets + [0.0, 3.0, 0.0]])                   # wobble: its list only
    sc.execute(GalvoDriver.from_config(rig.operator.head).compile(beside)[0])
    assert len(sc.burns) == 2 and sc.burns[1].passes == 1
    assert np.nanmean(sc.burns[1].widths) == pytest.approx(np.nanmean(plain.burns[0].widths),
                                                           rel=0.02)
