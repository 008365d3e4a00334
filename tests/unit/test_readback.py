"""Reading marks back: the camera's image rectified onto the surface (planar and wrap) puts a
known pattern where it is, the measured surface hides what the camera cannot see, and a code's
grade follows the mark's quality (marked on the simulated rig:
tests/integration/test_readback_marked.py)."""


import numpy as np
import pytest
from scipy import ndimage

from insitu.geometry.camera import CameraModel
from insitu.marking import Placement
from insitu.marking.project import Projection
from insitu.marking.readback import find_offset
from insitu.marking.rectify import mark_frame, occluded, rectify, surface_points
from insitu.marking.surface import Surface
from insitu.patterns.model import Pattern

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
