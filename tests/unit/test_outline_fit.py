"""A scan reference's outline fitted (:mod:`insitu.locate.outline_fit`): edge points become
lines and circles, split at corners; the fitted outline redrawn into the height image is
where the scan lines' edge step finds the edges; a recorded scan's room-light frame gives
the step block's sides where they are."""

import json
from pathlib import Path

import numpy as np

from insitu.locate.height_image import HeightImage
from insitu.locate.image_edges import Outline
from insitu.locate.outline_fit import stamp
from insitu.locate.pieces import pieces as _pieces

DATA = Path(__file__).resolve().parents[1] / "data"


def test_a_line_a_circle_and_a_corner():
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 12.0, 0.05)
    line = np.column_stack([t, 0.3 * t]) + rng.normal(0, 0.02, (len(t), 2))
    n = np.tile([-0.3, 1.0] / np.hypot(0.3, 1.0), (len(t), 1))
    (p,) = _pieces(line, n, np.zeros(len(t)), 0.05, "frame")
    drops = p.outward * np.array([-p.axis[1], p.axis[0]])
    assert p.kind == "line" and np.allclose(drops, n[0], atol=1e-3)
    assert abs(p.length_mm - 12 * np.hypot(1, 0.3)) < 0.2
    assert abs(abs(p.axis @ [1.0, 0.3]) / np.hypot(1, 0.3) - 1) < 1e-4 and p.rms_mm < 0.03
    a = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    ring = 1.9 * np.column_stack([np.cos(a), np.sin(a)]) + rng.normal(0, 0.01, (300, 2))
    (c,) = _pieces(ring, -ring / 1.9, np.zeros(300), 0.05, "frame")   # a hole: drops inward
    assert c.kind == "circle" and abs(c.radius_mm - 1.9) < 0.01 and c.outward == -1.0
    assert np.allclose(c.centre, 0, atol=0.01) and abs(c.length_mm - 2 * np.pi * 1.9) < 0.1
    ell = np.vstack([np.column_stack([t, np.zeros(len(t))]),
                     np.column_stack([np.full(len(t), 12.0), t])])
    normals = np.vstack([np.tile([0.0, -1.0], (len(t), 1)), np.tile([1.0, 0.0], (len(t), 1))])
    got = _pieces(ell, normals, np.zeros(len(ell)), 0.05, "frame")
    assert sorted(p.kind for p in got) == ["line", "line"]
    assert all(abs(p.length_mm - 12) < 0.5 for p in got)


def test_stray_edge_points_do_not_turn_a_side_and_its_sigma_is_its_scatters():
    """A 20 mm side with 2 % of its edge points 0.3–0.7 mm off (a shadow's step): fitted
    robustly, it stays within 0.005 mm of the true side end to end (least squares turned it
    by several hundredths); its 1σ and its turn's follow its scatter over 2 mm stretches."""
    from insitu.locate.pieces import CORRELATED_MM

    rng = np.random.default_rng(5)
    t = np.arange(0.0, 20.0, 0.05)
    off = rng.normal(0, 0.02, len(t))
    stray = rng.choice(len(t) // 2, len(t) // 50, replace=False)
    off[stray] += rng.uniform(0.3, 0.7, len(stray))
    xy = np.column_stack([t, off])
    (p,) = _pieces(xy, np.tile([0.0, 1.0], (len(t), 1)), np.zeros(len(t)), 0.05, "frame")
    ends = p.distance(np.array([[0.0, 0.0], [20.0, 0.0]]))
    assert np.all(np.abs(ends) < 0.005), ends
    m = xy.mean(axis=0)
    axis = np.linalg.svd(xy - m, full_matrices=False)[2][0]
    plain = ((np.array([[0.0, 0.0], [20.0, 0.0]]) - m) @ [-axis[1], axis[0]])
    assert np.abs(plain).max() > 4 * np.abs(ends).max()       # least squares: turned
    n = 20.0 / CORRELATED_MM
    assert np.isclose(p.sigma_mm, 0.02 / np.sqrt(n), rtol=0.2)
    assert np.isclose(p.tilt_mm, np.sqrt(3) * p.sigma_mm)


def test_the_stamped_edge_is_where_the_outline_puts_it():
    """A blurred step (a splat's) redrawn on an outline 0.23 mm further out: the height falls
    halfway there."""
    from insitu.locate.edge_align import _crossing

    x = np.arange(-5.0, 5.0, 0.1)
    z = np.tile(10.0 / (1 + np.exp(x / 0.1)), (60, 1)).astype(np.float32)   # edge at x = 0
    heights = HeightImage(z, -5.0, -3.0, 0.1)
    ys = np.arange(-2.0, 2.0, 0.05)
    edges = Outline(np.column_stack([np.full(len(ys), 0.23), ys, np.full(len(ys), 10.0)]),
                    np.tile([1.0, 0.0], (len(ys), 1)), np.zeros(len(ys)))
    e = np.array([[-0.5, 0.0, 10.0]])
    before = _crossing(heights, e, np.array([[1.0, 0.0]]))[0] - 0.5
    after = _crossing(stamp(heights, edges), e, np.array([[1.0, 0.0]]))[0] - 0.5
    assert abs(before) < 0.02 and abs(after - 0.23) < 0.02


def test_a_recorded_scans_frame_gives_the_blocks_sides():
    """The binning-4 recording of the step block with its room-light frame: its long sides
    (x = ±10 mm, the block at the origin) fitted within a third of a pixel (0.35 mm a pixel);
    the recipe's report gives its edges' 1σ."""
    from insitu.formats.camera_spec import CameraSpec
    from insitu.formats.sequence import Sequence
    from insitu.locate.reference import reference_from_cloud
    from insitu.services import scan_replay
    from insitu.services.common import camera_model

    scan = DATA / "scan-step-block-b4"
    cloud = scan_replay(scan).cloud
    seq = Sequence.open(scan)
    camera = camera_model(CameraSpec.model_validate(
        json.loads((scan / "sequence.json").read_text())["camera"]))
    ref = reference_from_cloud(cloud.points, "b4", image=seq.read_ambient(), camera=camera,
                               lines=cloud.attributes["line"])
    sides = [p for p in ref.fitted.pieces if p.kind == "line" and abs(p.axis[1]) > 0.99
             and p.length_mm > 10]
    assert sides, [(p.kind, p.centre, p.length_mm) for p in ref.fitted.pieces]
    for p in sides:
        assert abs(abs(p.centre[0]) - 10.0) < 0.12, p.centre
    assert 0.3 < ref.fitted.covered <= 1.0
    from insitu.services.reference_outline import outline_findings

    found = {label: (level, text) for level, label, text in outline_findings(ref)}
    fit = found["fit"][1]
    lo, hi = ref.fitted.outline.sigma_mm.min(), ref.fitted.outline.sigma_mm.max()
    assert f"1σ {lo:.3f}–{hi:.3f} mm" in fit and 0.01 < lo <= hi, fit
    # each edge's scatter and 1σ, the longest first
    edges = found["edges"][1]
    longest = max(ref.fitted.pieces, key=lambda p: p.length_mm)
    assert edges.split(": ", 1)[1].count(" / ") == 2 * len(ref.fitted.pieces), edges
    assert f"{longest.kind} {longest.length_mm:.0f} / {1000 * longest.rms_mm:.0f} / " in edges
    # what its outline pins: x, y and the turn each to a 1σ; a tolerance it cannot hold warned
    from insitu.locate.uncertainty import outline_hold

    o = ref.fitted.outline
    h = outline_hold(o.points[:, :2], o.normals, o.points[:, 2], o.sigma_mm, o.tilt_mm, ref.rim)
    assert f"along x to {h.x_mm:.3f} mm, along y to {h.y_mm:.3f} mm" in found["pins"][1]
    # its frame shows the block's long sides and 5 mm of one end (the scan's 1 mm lines
    # check it at 2 samples, not enough: it counts 0.1 mm): x pinned, y only to 0.1 mm and the
    # turn (0.15° 1σ) by the long sides pieced from 9-18 mm stretches at four heights — so
    # parts located against it will be refused, and the report says so
    assert 0.003 < h.x_mm < 0.05 < 0.08 < h.y_mm, (h.x_mm, h.y_mm)
    level, text = found["pinned"]
    assert level == "warning" and "weakest its turn" in text and "CAD mesh" in text, text


def test_a_frame_edge_the_scans_top_runs_across_is_left_out():
    """A flat top (x < 0, 5 mm high; the scan's points 0.25 mm apart) whose room-light frame
    shows its side at x = 0 and a shadow's edge 1.5 mm inside it, both fitted to 0.02 mm rms:
    the scan's top ends at the side (nothing beyond it but the table) and runs on across the
    shadow's edge, which is left out — it would claim its offset to 0.01 mm while 1.5 mm off."""
    from insitu.locate.frame_pieces import CONTINUED, continued, where_the_top_ends
    from insitu.locate.pieces import fitted

    g = np.arange(-10.0, 0.0, 0.25)
    x, y = np.meshgrid(g + 0.125, np.arange(-8.0, 8.0, 0.25))
    part = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, 5.0)])
    rng = np.random.default_rng(3)
    ys = np.arange(-6.0, 6.0, 0.1)
    xy = np.vstack([np.column_stack([np.full(len(ys), at), ys]) for at in (0.0, -1.5)])
    xy[:, 0] += rng.normal(0.0, 0.02, len(xy))
    found = fitted(xy, np.tile([1.0, 0.0], (len(xy), 1)), np.full(len(xy), 5.0), 0.1)
    assert len(found) == 2 and all(p.sigma_mm < 0.02 for p in found)
    side, shadow = sorted(found, key=lambda p: -p.centre[0])
    assert abs(side.centre[0]) < 0.02 and abs(shadow.centre[0] + 1.5) < 0.02
    assert continued(side, part) < 0.05
    assert continued(shadow, part) > 1.5 * CONTINUED
    assert where_the_top_ends(found, part) == [side]


def test_a_top_the_camera_sees_at_a_grazing_angle_is_not_checked_by_the_lines():
    """The simulated arc's cylindrical top (width 40, sagitta 5: 28° at its ends) seen by the
    rig's camera, 25° off the vertical on the −x side: its far end's top (+x) at about 53°,
    counted as not checked however many lines cross it (its frame edge and its few lines'
    ends lay 0.05–0.07 mm out together); its near end and a flat top checked."""
    from dataclasses import replace

    from insitu.locate.outline_fit import GRAZING_DEG, checked, view_deg
    from insitu.locate.pieces import Piece
    from insitu.sim.rig import default_rig

    camera = default_rig(binning=8).operator.camera
    px = 0.1
    x, y = np.meshgrid(np.arange(-25.0, 25.0, px), np.arange(-25.0, 25.0, px))
    radius = (20.0 ** 2 + 5.0 ** 2) / 10.0
    z = np.where((np.abs(x) <= 20) & (np.abs(y) <= 20),
                 11.5 - radius + np.sqrt(np.maximum(radius ** 2 - x ** 2, 0.0)), 0.0)
    heights = HeightImage(z.astype(np.float32), -25.0, -25.0, px)
    flat = HeightImage(np.where(z > 0, 8.0, 0.0).astype(np.float32), -25.0, -25.0, px)

    def end(sign: float) -> Piece:
        return Piece("line", np.array([20.0 * sign, 0.0]), np.array([0.0, 1.0]), np.inf,
                     -sign, (-18.0, 18.0), 36.0, 0.02, 360, 6.5, scan=60, directions=1,
                     offset_mm=0.01)
    far, near = end(1.0), end(-1.0)
    angles = [view_deg(h, q, camera) for h, q in ((heights, far), (heights, near), (flat, far))]
    assert angles[0] > GRAZING_DEG > 35.0 > angles[2] and angles[1] < 15.0, angles
    assert [checked(replace(q, view_deg=a)) for q, a in zip((far, near, far), angles)] == [
        False, True, True]
    assert not checked(replace(near, view_deg=angles[1], scan=2))
