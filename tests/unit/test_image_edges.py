"""Locating from the room-light frame's edges (:mod:`insitu.locate.image_edges`): the
insert turned to within 0.04° by them (its scan lines' ends leave 0.05–0.15°); a frame
without the part or of another size is not used, and says why; one showing it elsewhere
refuses the part;
``insitu scan --room-light`` writes the frame, ``insitu locate --room-light`` needs the camera."""

import numpy as np
import pytest
from test_locate import synthetic_scan
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.images import read_image
from insitu.geometry.pose import pose_matrix
from insitu.locate.image_edges import align_image
from insitu.locate.part import LocateRefused, LocateSettings, locate_part
from insitu.locate.reference import reference_from_mesh
from insitu.services.room_light import station_room_light
from insitu.services.station import simulated
from insitu.sim.rig import default_rig
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld, sim_world

POSE = (6.0, -4.0, 37.0)
LOOSE = LocateSettings(tolerance_mm=0.1, turn_bound_deg=0.5)
"""The insert's turn is known to 0.1° (1σ) at binning 2: the gate lifted, these tests are
about which edges place it."""


@pytest.fixture(scope="module")
def rig():
    return default_rig(seed=0, binning=2)


@pytest.fixture(scope="module")
def insert():
    w = make_workpiece("insert")
    return reference_from_mesh(w.vertices, w.triangles, "insert")


@pytest.fixture(scope="module")
def posed(rig):
    """The room-light frame of the insert at ``POSE``."""
    return _frame(sim_world("insert", rig=rig, pose=POSE))


def _frame(world):
    with simulated(world) as station:
        return station_room_light(station).image


def _errors(angle_deg, xy, pose):
    return (float(np.hypot(xy[0] - pose[0], xy[1] - pose[1])),
            abs((angle_deg - pose[2] + 60.0) % 120.0 - 60.0))


def test_the_frames_edges_turn_the_insert_within_four_hundredths_of_a_degree(rig, insert,
                                                                           posed):
    image = posed
    start = pose_matrix(POSE[0] + 0.04, POSE[1] - 0.03, POSE[2] + 0.12)
    given = start.copy()
    fit = align_image(image, rig.camera, insert.heights, insert.outline, start)
    assert not isinstance(fit, str), fit
    assert np.array_equal(start, given)               # the start pose is the caller's, unmoved
    xy, turn = _errors(np.degrees(fit.angle_rad), fit.xy_mm, POSE)
    assert xy < 0.01 and turn < 0.04, (xy, turn)
    # its σ counts a bias per side (0.1 px) and a tilt (0.03 px; its sides cross 11 pixel
    # rows and more): the turn within 3σ, and 3σ within the 0.1° a pose is given at
    assert fit.edges > 0.8 * fit.visible and turn < 3 * fit.sigma_deg < 0.1


def test_a_wide_search_for_a_start_stops_near_and_takes_a_ready_frame(rig, insert, posed,
                                                                    monkeypatch):
    from insitu.locate import image_edges

    image = posed
    start = pose_matrix(POSE[0] + 0.3, POSE[1] - 0.2, POSE[2] + 0.3)
    steps = []
    edge_points = image_edges.edge_points
    monkeypatch.setattr(image_edges, "edge_points", lambda *a: steps.append(1) or edge_points(*a))
    full = align_image(image, rig.camera, insert.heights, insert.outline, start, search_px=12.0)
    n_full, steps[:] = len(steps), []
    near = align_image(image_edges.frame_of(image), rig.camera, insert.heights,
                       insert.outline, start, search_px=12.0, near_mm=0.01)
    assert not isinstance(full, str) and not isinstance(near, str), (full, near)
    assert len(steps) < n_full                       # its last, smallest step left out
    assert np.hypot(*(near.xy_mm - full.xy_mm)) < 0.01
    assert abs(near.angle_rad - full.angle_rad) < 0.01 / 50
    again = align_image(image_edges.frame_of(image), rig.camera, insert.heights,
                        insert.outline, start, search_px=12.0)
    # the same fit as from the image, to its own stop (0.001 mm, 0.001°)
    assert np.hypot(*(again.xy_mm - full.xy_mm)) < 1e-3
    assert abs(again.angle_rad - full.angle_rad) < 2e-5


def test_a_frame_without_the_part_or_of_another_camera_is_not_used(rig, insert):
    table = _frame(SimWorld(rig, parts=[], seed=0))
    start = pose_matrix(*POSE)
    why = align_image(table, rig.camera, insert.heights, insert.outline, start)
    assert isinstance(why, str) and "not the part's edges" in why
    why = align_image(table[:100], rig.camera, insert.heights, insert.outline, start)
    assert isinstance(why, str) and "px" in why


def test_locate_takes_the_frames_edges_only_where_they_agree_with_the_scan(rig, insert):
    points, lines = synthetic_scan("insert", POSE, noise=0.05)
    near = (POSE[2] - 30.0, POSE[2] + 30.0)
    alone = locate_part(insert, points, LOOSE, lines=lines, prefer_angle=near).best
    here = _frame(sim_world("insert", rig=rig, pose=POSE))
    got = locate_part(insert, points, lines=lines, prefer_angle=near, camera=rig.camera,
                      image=here).best     # within the rim's tolerance and the turn's bound
    assert got.image_edges > 0 and got.image_note == ""
    xy, turn = _errors(got.angle_deg, (got.x_mm, got.y_mm), POSE)
    assert xy < 0.01 and turn < 0.04, (xy, turn)
    # a frame of the part 0.4 mm away (it moved): the two disagree beyond their σ — refused,
    # neither pose given; the refused one is the scan's
    elsewhere = _frame(sim_world("insert", rig=rig, pose=(POSE[0] + 0.4, POSE[1], POSE[2])))
    with pytest.raises(LocateRefused, match="do not agree.*did the part move") as e:
        locate_part(insert, points, LOOSE, lines=lines, prefer_angle=near, camera=rig.camera,
                    image=elsewhere)
    kept = e.value.best
    assert kept.image_edges == 0
    assert (kept.x_mm, kept.y_mm, kept.angle_deg) == (alone.x_mm, alone.y_mm, alone.angle_deg)


def test_the_command_wants_the_camera_for_a_room_light_frame(tmp_path):
    frame = tmp_path / "room.png"
    frame.write_bytes(b"")
    got = CliRunner().invoke(app, ["locate", "part.stl", "cloud.ply", "-o",
                                   str(tmp_path / "pose.json"), "--room-light", str(frame)])
    assert got.exit_code != 0 and "--room-light needs --height-cal" in got.output
    assert not (tmp_path / "pose.json").exists()


def test_the_frame_places_a_part_the_scan_lines_leave_unheld(rig, insert):
    points, lines = synthetic_scan("insert", POSE, noise=0.05, spacing=2.0)
    near = (POSE[2] - 30.0, POSE[2] + 30.0)
    with pytest.raises(LocateRefused, match="not pinned down"):
        locate_part(insert, points, lines=lines, prefer_angle=near)
    here = _frame(sim_world("insert", rig=rig, pose=POSE))
    got = locate_part(insert, points, LOOSE, lines=lines, prefer_angle=near,
                      camera=rig.camera, image=here).best
    xy, turn = _errors(got.angle_deg, (got.x_mm, got.y_mm), POSE)
    assert got.image_edges > 0 and xy < 0.01 and turn < 0.04, (xy, turn)
    elsewhere = _frame(sim_world("insert", rig=rig, pose=(POSE[0] + 0.6, POSE[1], POSE[2])))
    with pytest.raises(LocateRefused, match="the room-light frame: not used"):
        locate_part(insert, points, lines=lines, prefer_angle=near, camera=rig.camera,
                    image=elsewhere)


def test_the_scan_command_writes_its_room_light_frame(tmp_path):
    got = CliRunner().invoke(app, ["scan", "-o", str(tmp_path / "part.ply"), "--workpiece",
                                   "insert", "--binning", "4", "--spacing", "0.5",
                                   "--room-light", str(tmp_path / "room.png")])
    assert got.exit_code == 0, got.output
    frame = read_image(tmp_path / "room.png")
    camera = default_rig(seed=0, binning=4).camera
    assert frame.shape == (camera.height, camera.width) and frame.max() > 100


def test_a_side_along_the_pixel_rows_is_named_as_what_holds_the_turn_back():
    from insitu.locate.image_edges import grid_note
    from insitu.locate.uncertainty import FRAME_TILT_PX, LOCK_PX

    assert grid_note(np.full(10, np.hypot(FRAME_TILT_PX, LOCK_PX / 20))) == ""
    note = grid_note(np.r_[np.full(5, FRAME_TILT_PX), np.hypot(FRAME_TILT_PX, LOCK_PX / 2)])
    assert "within 2.0 pixel rows" in note and "turned a few degrees" in note
    assert "within one pixel row" in grid_note(np.full(3, np.hypot(FRAME_TILT_PX, LOCK_PX)))


def test_a_crown_meeting_its_wall_at_a_shallow_angle_is_counted_less_sure():
    """The 8.5 mm crowned arc's sides: its top falls 46° into them, the grey step sits up to
    0.65 px outward (two renderers) — their bias counts SHOULDER times more; the 5 mm crown's
    (28°) and the arc's ends do not."""
    from insitu.locate.image_edges import SHOULDER, shoulder

    for sagitta, sides in ((8.5, SHOULDER), (5.0, 1.0)):
        w = make_workpiece("arc", sagitta=sagitta)
        ref = reference_from_mesh(w.vertices, w.triangles, "arc")
        o = ref.outline
        got = shoulder(ref.heights, o.points, o.normals)
        side = (np.abs(o.normals[:, 0]) > 0.99) & (np.abs(o.points[:, 1]) < 15)
        end = (np.abs(o.normals[:, 1]) > 0.99) & (np.abs(o.points[:, 0]) < 15)
        assert np.median(got[side]) == sides and np.all(got[end] == 1.0)
