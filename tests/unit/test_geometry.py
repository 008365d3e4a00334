"""Camera and beam models: round trips and known values from the papers' equations."""

import numpy as np
import pytest

from insitu.geometry.beams import PivotHead, ScanHeadOptics, TwoMirrorHead, light_plane, line_sheet
from insitu.geometry.camera import CameraModel
from insitu.geometry.distortion import PolynomialFieldDistortion, distortion_from_dict


def _camera():
    K = np.array([[4600.0, 0, 1223.5], [0, 4600.0, 1023.5], [0, 0, 1]])
    dist = np.array([-0.08, 0.12, 0.0004, -0.0003, -0.05])
    return CameraModel.look_at(2448, 2048, K, dist, [-150, 0, 330], [0, 0, 0], [0, 1, 0])


def _ray_hit_z(origin, dirs, z):
    s = (z - origin[..., 2]) / dirs[:, 2]
    return origin + s[:, None] * dirs


def test_camera_project_backproject_round_trip():
    cam = _camera()
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(-60, 60, 500), rng.uniform(-70, 70, 500),
                           rng.uniform(-20, 20, 500)])
    uv = cam.project(pts)
    assert cam.in_image(uv).all()
    origin, dirs = cam.rays(uv)
    hit = _ray_hit_z(origin, dirs, pts[:, 2])
    np.testing.assert_allclose(hit, pts, atol=1e-6)


def test_camera_frames_and_look_at():
    cam = _camera()
    np.testing.assert_allclose(cam.centre_world, [-150, 0, 330], atol=1e-9)
    np.testing.assert_allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-12)
    # the target lands near the principal point; world +y goes to +u (lines along y are rows)
    uv0, uv1 = cam.project(np.array([[0, 0, 0.0], [0, 10, 0.0]]))
    assert abs(uv0[0] - 1223.5) < 1 and abs(uv0[1] - 1023.5) < 1
    assert uv1[0] - uv0[0] > 100 and abs(uv1[1] - uv0[1]) < 5
    pts = np.array([[1.0, 2.0, 3.0]])
    np.testing.assert_allclose(cam.to_world(cam.to_camera(pts)), pts)
    np.testing.assert_allclose(cam.T_cam_world[:3, :3], cam.R)
    assert np.isnan(cam.project(np.array([[-400.0, 0, 600]]))).all()  # behind the camera


def test_camera_undistort_matches_pinhole():
    cam = _camera()
    ideal = CameraModel(cam.width, cam.height, cam.K, np.zeros(5), cam.R, cam.t)
    pts = np.array([[60.0, -70, 5], [-40, 80, -10]])
    np.testing.assert_allclose(cam.undistort(cam.project(pts)), ideal.project(pts), atol=1e-6)


def test_camera_dict_round_trip():
    cam = _camera()
    back = CameraModel.from_dict(cam.to_dict())
    np.testing.assert_allclose(back.K, cam.K)
    np.testing.assert_allclose(back.t, cam.t)


def test_two_mirror_known_values():
    head = TwoMirrorHead(mirror_distance_mm=350.0, mirror_separation_mm=12.0)
    # centre: zero angles and zero focus shift on any plane (Eq. 5)
    ax, ay, dfr = head.inverse(0.0, 0.0, 7.0)
    assert ax == 0 and ay == 0 and dfr == 0
    # Eq. 3: alpha_x = atan(x / (d - z)) / 2
    ax, ay, dfr = head.inverse(100.0, 0.0, 0.0)
    assert ax == pytest.approx(0.5 * np.arctan(100 / 350))
    assert dfr == pytest.approx(np.hypot(350, 100) - 350)
    # Eq. 4 with x = 0: alpha_y = atan(y / (e + d)) / 2
    ax, ay, dfr = head.inverse(0.0, 80.0, 0.0)
    assert ay == pytest.approx(0.5 * np.arctan(80 / 362))
    assert dfr == pytest.approx(np.hypot(362, 80) - 362)
    # focus on a plane 10 mm up shortens the path by 10 mm at the centre
    assert head.focus_shift(0.0, 0.0, 10.0) == pytest.approx(-10.0)


def test_two_mirror_forward_inverse_round_trip():
    head = TwoMirrorHead(350.0, 12.0)
    rng = np.random.default_rng(2)
    x, y, z = rng.uniform(-100, 100, 300), rng.uniform(-100, 100, 300), rng.uniform(-25, 25, 300)
    ax, ay, _ = head.inverse(x, y, z)
    xf, yf = head.forward(2 * ax, 2 * ay, z)
    np.testing.assert_allclose(xf, x, atol=1e-9)
    np.testing.assert_allclose(yf, y, atol=1e-9)
    # the ray of a command passes through the target at every height
    origins, dirs = head.rays(np.column_stack([x, y]))
    hit0 = _ray_hit_z(origins, dirs, np.zeros(300))
    np.testing.assert_allclose(hit0[:, :2], np.column_stack([x, y]), atol=1e-9)
    hitz = _ray_hit_z(origins, dirs, z)
    ax0, ay0, _ = head.inverse(x, y, 0.0)
    ax2, ay2, _ = head.inverse(hitz[:, 0], hitz[:, 1], z)
    np.testing.assert_allclose(ax2, ax0, atol=1e-12)
    np.testing.assert_allclose(ay2, ay0, atol=1e-12)
    # focus shift = path length along the ray from its origin to the target, minus the centre's
    path = np.linalg.norm(hitz - origins, axis=1) + head.mirror_separation_mm / np.cos(2 * ay0)
    centre = head.mirror_distance_mm + head.mirror_separation_mm
    np.testing.assert_allclose(head.focus_shift(hitz[:, 0], hitz[:, 1], z), path - centre,
                               atol=1e-9)


def test_line_along_y_is_the_pivot_models_plane():
    """A two-mirror line along y is exactly Li's light plane through (0, 0, d)."""
    head = TwoMirrorHead(350.0, 12.0)
    start, end = np.array([23.0, -45.0]), np.array([23.0, 45.0])
    cmd, origins, dirs = line_sheet(head, start, end, 50)
    plane = light_plane(350.0, start, end)
    for s in (0.0, 100.0, 340.0):
        pts = origins + s * dirs
        np.testing.assert_allclose(pts @ plane[:3] + plane[3], 0.0, atol=1e-9)


def test_pivot_and_telecentric_rays():
    cmd = np.array([[10.0, -20.0], [0.0, 0.0]])
    o, d = PivotHead(350.0).rays(cmd)
    np.testing.assert_allclose(o[0], [0, 0, 350])
    np.testing.assert_allclose(_ray_hit_z(o, d, np.zeros(2))[:, :2], cmd, atol=1e-12)
    o, d = PivotHead(350.0, telecentric=True).rays(cmd)
    np.testing.assert_allclose(d, [[0, 0, -1]] * 2)
    plane = light_plane(350.0, [5, -40], [5, 40], telecentric=True)
    np.testing.assert_allclose(np.abs(plane[:3]), [1, 0, 0], atol=1e-12)


def test_field_distortion_shifts_landing_and_round_trips():
    rng = np.random.default_rng(3)
    dist = PolynomialFieldDistortion.random(rng, rms_mm=0.8, half_field_mm=90)
    g = np.stack(np.meshgrid(np.linspace(-90, 90, 61), np.linspace(-90, 90, 61)), -1).reshape(-1, 2)
    shift = dist(g)
    rms = np.sqrt(np.mean(np.sum(shift**2, 1)))
    assert rms == pytest.approx(0.8, rel=0.05)
    assert 1.2 < np.max(np.linalg.norm(shift, axis=1)) < 3.5
    np.testing.assert_allclose(dist(np.zeros((1, 2))), 0.0, atol=1e-12)
    optics = ScanHeadOptics(TwoMirrorHead(350.0, 12.0), dist)
    o, d = optics.rays(g)
    np.testing.assert_allclose(_ray_hit_z(o, d, np.zeros(len(g)))[:, :2], g + shift, atol=1e-9)
    np.testing.assert_allclose(distortion_from_dict(dist.to_dict())(g), shift)
