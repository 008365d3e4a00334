"""The simulator is as hard as the world: along-line speckle of the measured statistics, a
mirror image of the line in a step wall, fixed-pattern noise, ambient light (docs/simulator.md)."""

import numpy as np
import pytest

from insitu.geometry.beams import line_commands
from insitu.sim.linestats import line_stats
from insitu.sim.render import Renderer
from insitu.sim.rig import default_rig
from insitu.sim.scene import Scene
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld


@pytest.fixture(scope="module")
def rig():
    return default_rig(seed=3, binning=2)


def test_metal_line_speckle_has_the_target_cv_and_correlation_length(rig):
    """On the step block's 10 mm top: CV ≥ 0.3, 1/e correlation length 0.15–0.35 mm."""
    r = SimWorld(rig, parts=[make_workpiece("step-block")], seed=4).renderer()
    cv, corr = [], []
    for x in (-5.0, 0.0, 5.0):
        img = r.line_frame([x, 1.0], [x, 19.0], exposure_ms=5.0, focus_z=10.0)
        a, b = rig.camera.project(np.array([[x, 10.0, 10.0], [x, 11.0, 10.0]]))
        s = line_stats(img, along="u", bright_only=False)
        assert s.n > 80 and s.saturated < 0.2
        cv.append(s.cv)
        corr.append(s.corr_px / np.linalg.norm(b - a))
    assert np.median(cv) >= 0.3, cv
    assert 0.15 <= np.median(corr) <= 0.35, corr


def test_step_wall_mirrors_the_line_at_10_to_40_percent(rig):
    """A line on the table 2 mm in front of the block's −x face: the face shows its mirror
    image a few px away, at 10–40 % of the line's brightness (ray traced, no painted stripe)."""
    scene = Scene([make_workpiece("table"), make_workpiece("step-block")], seed=1)
    r = Renderer(rig, scene, seed=1)
    cmd = line_commands(np.array([-12.0, -30.0]), np.array([-12.0, 30.0]), 3000)
    main = r._splat_hits(*rig.beams.rays(cmd), np.full(3000, rig.optics.line_power * 60 / 2999),
                         0.0, beam_blur=True)
    ghost = r._mirror_image(cmd, rig.optics.line_power, 0.0)
    cols = np.nonzero(ghost.max(0) > 0.05 * ghost.max())[0]
    assert len(cols) > 200
    ratio = ghost[:, cols].max(0) / main[:, cols].max(0)
    gap = np.abs(np.argmax(ghost[:, cols], 0) - np.argmax(main[:, cols], 0))
    assert 0.10 <= np.median(ratio) <= 0.40, np.median(ratio)
    assert 5 <= np.median(gap) <= 60                     # beside the line, inside the band
    assert Renderer(rig, scene, ideal=True).line_frame([-12.0, -30.0], [-12.0, 30.0]).max() > 0
    frame = r.line_frame([-12.0, -30.0], [-12.0, 30.0]).astype(float)
    bright = frame[:, cols].max(0)
    assert np.median(frame[np.argmax(ghost[:, cols], 0), cols] / bright) > 0.05


def test_fixed_pattern_noise_belongs_to_the_camera(rig):
    """Two frames of one camera share their fixed pattern; another rig seed has another."""
    scene = Scene([make_workpiece("table")])
    dark = [Renderer(rig, scene, seed=s).ambient_frame(0.0).astype(float) for s in (1, 2)]
    other = Renderer(default_rig(seed=4, binning=2), scene, seed=7).ambient_frame(0.0)
    g1, g2 = Renderer(rig, scene)._fixed_pattern(), Renderer(rig, scene, seed=9)._fixed_pattern()
    assert np.array_equal(g1[0], g2[0]) and np.array_equal(g1[1], g2[1])
    mean = (dark[0] + dark[1]) / 2
    assert np.corrcoef((dark[0] - mean.mean()).ravel(), (dark[1] - mean.mean()).ravel())[0, 1] > 0.2
    assert abs(np.corrcoef(dark[0].ravel(), other.astype(float).ravel())[0, 1]) < 0.05


@pytest.mark.parametrize("pose", [(6.0, -4.0, 37.0), (-3.0, 5.0, 2.0), (10.0, 2.0, 91.0)])
def test_a_parts_edges_fall_between_pixels_in_the_room_light(rig, pose):
    """A pixel a part's edge crosses integrates its area (one ray per pixel, or a half-size
    map enlarged, puts the edge on whole pixels): the insert's top edges in the noise-free
    room light — the renderer's (the laser frames' background, the laser-off frame) and the
    inspection frame's — lie on its outline within 0.04 mm (robust 1σ; 0.155 mm pixels; the
    half-size map 0.062–0.074) and turn it less than 0.04°."""
    from insitu.geometry.pose import pose_matrix
    from insitu.locate.image_edges import align_image
    from insitu.locate.reference import reference_from_mesh
    from insitu.sim.marks import render_inspection

    part = make_workpiece("insert")
    ref = reference_from_mesh(part.vertices, part.triangles, "insert")
    world = SimWorld(rig, parts=[make_workpiece("insert", x=pose[0], y=pose[1],
                                                angle_deg=pose[2])], seed=0)
    scene = world.renderer().scene
    for light in (world.renderer()._ambient_image(),
                  render_inspection(rig, scene, [], ideal=True)):
        fit = align_image(light * (180 / np.percentile(light, 99.5)), rig.camera, ref.heights,
                          ref.outline, pose_matrix(*pose))
        assert not isinstance(fit, str), fit
        assert fit.rms_mm < 0.04 and abs(np.degrees(fit.angle_rad) - pose[2]) < 0.04, fit


def test_ambient_light_on_the_part_is_10_to_20_dn_with_texture(rig):
    world = SimWorld(rig, parts=[make_workpiece("step-block")], seed=1)
    amb = world.renderer().ambient_frame().astype(float)
    o, d = rig.camera.rays(np.array([[u, v] for u in range(0, rig.camera.width, 8)
                                      for v in range(0, rig.camera.height, 8)], float))
    hits = world.renderer().scene.cast(np.tile(o, (len(d), 1)), d)
    on_part = hits.hit & (hits.part == 1)
    uv = np.array([[u, v] for u in range(0, rig.camera.width, 8)
                   for v in range(0, rig.camera.height, 8)])[on_part]
    level = amb[uv[:, 1], uv[:, 0]]
    assert 10 <= np.median(level) <= 20, np.median(level)
    assert np.std(level) > 1.0                                  # textured, shaded
