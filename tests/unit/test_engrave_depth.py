"""A pocket's depth from one scan, without the renderer: the top's model (a plane unless the
top is curved), the walls' bias zone set by the local depth, line offsets only where the
lines show them, and the pocket's depth refused when it is not known to the tolerance."""

from dataclasses import replace

import numpy as np
import pytest
import shapely

from insitu.errors import MeasurementError
from insitu.marking.engrave_depth import MEASURED, DepthSettings, measure_depth
from insitu.marking.engrave_stats import texture_var
from insitu.marking.engrave_top import top_model
from insitu.services.engrave_request import LOOP_DEPTH

POCKET = shapely.box(-1.0, -1.0, 1.0, 1.0)


def _scan(rng, depth: float, noise, curve: float = 0.0, spacing: float = 0.1):
    """Lines along y ``spacing`` mm apart over a 2 × 2 mm pocket ``depth`` deep in a top at
    5 mm, tilted (and bent by ``curve`` mm/mm²), points 0.075 mm apart each off by
    ``noise(rng, n)`` mm: (points (N, 3), line (N,))."""
    pts, line = [], []
    y = np.arange(-2.5, 2.5, 0.075)
    for k, x in enumerate(np.arange(-2.45, 2.46, spacing)):
        inside = (np.abs(x) < 1.0) & (np.abs(y) < 1.0)
        z = 5.0 + 0.006 * x - 0.003 * y + curve * (x * x + y * y) - np.where(inside, depth, 0)
        pts.append(np.column_stack([np.full(len(y), x), y, z + noise(rng, len(y))]))
        line.append(np.full(len(y), k))
    return np.vstack(pts), np.concatenate(line)


def _heavy(scale: float):
    """Centre errors with heavy tails (Student's t, 3 degrees of freedom) as speckle gives."""
    return lambda rng, n: scale * rng.standard_t(3, n)


def _ring(p, line):
    far = (np.abs(p[:, 0]) > 1.2) | (np.abs(p[:, 1]) > 1.2)
    return p[far], line[far]


def test_a_flat_top_is_a_plane_a_curved_one_a_quadratic():
    """Around a hole, the top is fitted as a plane unless its curvature shows (a quadratic's
    extra terms would carry the top's noise into the hole's middle)."""
    rng = np.random.default_rng(0)
    flat = top_model(*_ring(*_scan(rng, 0.1, _heavy(0.02))))
    bent = top_model(*_ring(*_scan(rng, 0.1, _heavy(0.02), curve=0.01)))
    assert flat.coef.size == 3 and bent.coef.size == 6
    assert flat.sem(np.zeros((1, 2))) < 0.001


def test_heavy_tailed_noise_alone_is_not_taken_for_line_offsets():
    """Points with heavy-tailed errors (35 µm scale) and no error shared by a line: over four
    scans the top's line offsets stay under 1 µm rms (with a line mean's noise from the
    points' MAD they came out 2 µm, up to 8 µm on the simulated plate, and the floor took
    them on)."""
    offsets = []
    for seed in range(10, 14):
        top = top_model(*_ring(*_scan(np.random.default_rng(seed), 0.1, _heavy(0.035))))
        offsets += list(top.offsets.values())
    assert np.sqrt(np.mean(np.square(offsets))) < 0.001


def test_the_walls_bias_zone_is_set_by_the_local_depth_not_each_points_own():
    """A shallow pocket read with 40 µm noise and a bias zone of 5 mm per mm of depth: a zone
    from each point's own depth would keep the shallow-reading points near the walls and
    drop the deep-reading ones (the mean depth ~5 σ shallow); from the local depth it is not
    biased."""
    rng = np.random.default_rng(2)
    p, line = _scan(rng, 0.05, lambda rng, n: 0.04 * rng.standard_normal(n), spacing=0.02)
    s = DepthSettings(ring_mm=1.5, bias_per_depth=5.0)
    mean, sem = measure_depth(p, line, POCKET, s).mean_depth()
    assert abs(mean - 0.05) < 3 * sem


def test_the_pockets_depth_error_is_honest_and_refused_beyond_the_tolerance():
    """The depth's standard error counts the floor's lines and the top's error: over eight
    scans the errors spread as it says; a noisy scan's depth is refused at 5 µm, a quiet
    one's given."""
    z = []
    for seed in range(8):
        rng = np.random.default_rng(10 + seed)
        line_err = 0.006 * rng.standard_normal(100)
        p, line = _scan(rng, 0.2, _heavy(0.02))
        p[:, 2] += line_err[line]
        dm = measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5))
        mean, sem = dm.mean_depth()
        z.append((mean - 0.2) / sem)
    assert 0.5 < np.sqrt(np.mean(np.square(z))) < 1.5
    noisy = measure_depth(*_scan(np.random.default_rng(3), 0.2, _heavy(0.05)), POCKET,
                          DepthSettings(ring_mm=1.5))
    with pytest.raises(MeasurementError, match="not to the ±5.0 µm asked"):
        noisy.pocket_depth(0.005)
    quiet = measure_depth(*_scan(np.random.default_rng(4), 0.2, _heavy(0.005)), POCKET,
                          DepthSettings(ring_mm=1.5))
    assert quiet.pocket_depth(0.005)[0] == pytest.approx(0.2, abs=0.003)


def test_lines_that_happen_to_agree_do_not_shrink_the_depths_error():
    """Each line's floor points scatter by 50 µm in grains 0.5 mm long (the speckle's) yet
    every line's mean is nearly the same: the lines' scatter says 1.7 µm, the grains along
    them 3.0 µm, and the depth's error is the larger; refused at ±5 µm."""
    rng = np.random.default_rng(5)
    p, line = _scan(rng, 0.1, lambda rng, n: 0.0005 * rng.standard_normal(n))
    floor = (np.abs(p[:, 0]) < 1.0) & (np.abs(p[:, 1]) < 1.0)
    grain = 0.05 * rng.standard_normal((line.max() + 1, 10))[line, ((p[:, 1] + 2) // 0.5)
                                                             .astype(int)]
    for k in np.unique(line[floor]):
        on = floor & (line == k)
        p[on, 2] -= grain[on] - grain[on].mean()
    dm = measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5))
    assert 0.0025 < dm.mean_depth()[1] < 0.006
    with pytest.raises(MeasurementError, match="not to the ±5.0 µm asked"):
        dm.pocket_depth(0.005)


def test_a_wall_parallel_to_the_scan_lines_keeps_a_narrower_zone():
    """A 2 × 2 mm pocket 0.2 mm deep whose floor within 0.2 mm of the walls the lines cross
    reads 30 µm short: those points are left out, the cells 0.125 mm from a wall parallel to
    the lines (not straddled by them) are measured, none 0.125 mm from a crossed wall; the
    same scan turned a quarter (lines along x) swaps the walls' roles."""
    rng = np.random.default_rng(5)
    p, line = _scan(rng, 0.2, lambda rng, n: 0.003 * rng.standard_normal(n), spacing=0.05)
    p[:, 2] += np.where((np.abs(p[:, 0]) < 1) & (np.abs(p[:, 1]) > 0.8) & (np.abs(p[:, 1]) < 1),
                        0.03, 0.0)
    s = DepthSettings(ring_mm=1.5)
    for turned in (False, True):
        q = p[:, [1, 0, 2]] if turned else p
        dm = measure_depth(q, line, POCKET, s)
        gx, gy = dm.cells.centres()
        across, along = (gy, gx) if turned else (gx, gy)
        measured = dm.state == MEASURED
        beside_parallel = (np.abs(np.abs(across) - 0.875) < 0.01) & (np.abs(along) < 0.6)
        beside_crossed = (np.abs(np.abs(along) - 0.875) < 0.01) & (np.abs(across) < 0.6)
        assert measured[beside_parallel].all() and not measured[beside_crossed].any()
        assert np.nanmax(np.abs(dm.depth[measured] - 0.2)) < 0.003


def test_the_wall_facing_the_camera_keeps_its_mirror_ghost_off_the_floor():
    """A specular blank's wall facing the camera mirrors the floor's line beside it: the lines
    0.1–0.4 mm from it read up to 30 µm short (the simulator, stainless 0.1–0.5 mm deep).
    With the camera's place known those lines are left out and the depth is right; the wall
    on the far side (the camera on the other side) keeps its narrow zone."""
    rng = np.random.default_rng(6)
    p, line = _scan(rng, 0.1, lambda rng, n: 0.003 * rng.standard_normal(n), spacing=0.05)
    ghost = (np.abs(p[:, 1]) < 1) & (p[:, 0] > 0.6) & (p[:, 0] < 0.9)
    p[ghost, 2] += 0.03 * (p[ghost, 0] - 0.6) / 0.3
    s = DepthSettings(ring_mm=1.5)
    pivot = [0.0, 0.0, 350.0]
    faced = measure_depth(p, line, POCKET, s, viewpoints=np.array([[-150, 0, 330], pivot]))
    far = measure_depth(p, line, POCKET, s, viewpoints=np.array([[150, 0, 330], pivot]))
    assert abs(faced.mean_depth()[0] - 0.1) < 0.001
    assert far.mean_depth()[0] < 0.1 - 0.002
    measured = faced.state == MEASURED
    gx, _ = faced.cells.centres()
    assert not measured[gx > 0.6].any() and measured[np.abs(gx + 0.875) < 0.01].any()


def test_the_engravings_maps_keep_the_cells_beside_the_faced_wall():
    """The engraving's maps between rounds keep the faced wall's cells (leaving them out did
    not help its tune seeds), where a pocket's depth leaves them out."""
    p, line = _scan(np.random.default_rng(7), 0.1, lambda rng, n: 0.003 * rng.standard_normal(n),
                    spacing=0.05)
    vp = np.array([[-150, 0, 330], [0.0, 0.0, 350.0]])
    loop = measure_depth(p, line, POCKET, replace(LOOP_DEPTH, ring_mm=1.5), viewpoints=vp)
    depth = measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5), viewpoints=vp)
    gx, _ = loop.cells.centres()
    beside = np.abs(gx - 0.625) < 0.01
    assert (loop.state[beside] == MEASURED).any()
    assert not (depth.state[beside] == MEASURED).any()


def _ringed(rng, shift: float, period: float = 3.0, rings: float = 0.12):
    """Lines along y 0.1 mm apart over a 4 × 4 mm pocket whose floor is 0.2 mm ± ``rings`` in
    bands ``period`` mm apart across y (a wood's rings), each point placed ``shift`` mm off
    along the line (a camera's calibration error), 5 µm noise, points 0.075 mm apart from a
    place drawn for each line: (points, line, the floor's depth at world x, y)."""
    def floor(x, y):
        return 0.2 * (1 + rings * np.sin(2 * np.pi * y / period + 0.4))
    pts, line = [], []
    for k, x in enumerate(np.arange(-2.45, 2.46, 0.1)):
        y = np.arange(-4.0, 4.0, 0.075) + rng.uniform(0, 0.075)
        inside = (np.abs(x) < 2.0) & (np.abs(y) < 2.0)
        z = 5.0 + 0.004 * x - np.where(inside, floor(x, y), 0.0)
        pts.append(np.column_stack([np.full(len(y), x), y + shift,
                                    z + 0.005 * rng.standard_normal(len(y))]))
        line.append(np.full(len(y), k))
    return np.vstack(pts), np.concatenate(line), floor


def test_the_loops_map_is_put_on_the_walls_the_lines_cross():
    """A scan placed 0.2 mm off along its lines (the camera's calibration) reads a floor that
    is not flat where it is not: every cell the floor's slope × 0.2 mm off, the same each
    scan. The loop's map finds the shift from the walls the lines cross (within 0.02 mm) and
    its cells' error falls to a third of the map's unregistered."""
    p, line, floor = _ringed(np.random.default_rng(8), 0.2)
    region = shapely.box(-2.0, -2.0, 2.0, 2.0)
    errs = []
    for s in (replace(LOOP_DEPTH, ring_mm=1.5), DepthSettings(ring_mm=1.5, register_mm=0.0)):
        dm = measure_depth(p, line, region, s)
        gx, gy = dm.cells.centres()
        off = (np.arange(5) - 2) * dm.cells.cell_mm / 5
        truth = np.mean([floor(gx + a, gy + b) for a in off for b in off], axis=0)
        ok = (dm.state == MEASURED) & (dm.cells.edge_mm > 0.5)
        errs.append(float(np.sqrt(np.mean((dm.depth - truth)[ok] ** 2))))
        if s.register_mm:
            assert abs(dm.shift_mm - 0.2) < 0.02
        else:
            assert dm.shift_mm == 0.0
    assert errs[0] < errs[1] / 3 and errs[1] > 0.005


def test_a_floor_the_kernel_flattens_widens_its_cells_error():
    """Rings 1.5 mm apart (beech's) read flattened by the map's 0.2 mm kernel: each cell off by
    ~5 µm rms from its mean, the same every scan, far beyond its noise's standard error. The
    cells' σ takes it from the map itself (|err|/σ rms below 1.5, ~4 without it); on a flat
    floor it adds under 1 µm."""
    ratios = []
    for rings in (0.12, 0.0):
        p, line, floor = _ringed(np.random.default_rng(9), 0.0, 1.5, rings)
        dm = measure_depth(p, line, shapely.box(-2.0, -2.0, 2.0, 2.0), DepthSettings(ring_mm=1.5))
        gx, gy = dm.cells.centres()
        off = (np.arange(5) - 2) * dm.cells.cell_mm / 5
        truth = np.mean([floor(gx + a, gy + b) for a in off for b in off], axis=0)
        ok = (dm.state == MEASURED) & (dm.cells.edge_mm > 0.5)
        ratios.append(float(np.sqrt(np.mean(((dm.depth - truth) / dm.sem)[ok] ** 2))))
        if not rings:
            assert texture_var(dm.depth, dm.state == MEASURED, 0.25, 0.2) < 0.001 ** 2
    assert ratios[0] < 1.5


def test_a_crossed_scan_is_refused_one_pass_is_measured():
    """Lines of two directions over the pocket (a crossed scan) are refused in one line: the
    walls' zones, the scatter along the lines and the registration take one direction; the
    same pass alone, or lines a few degrees off one another, are measured."""
    rng = np.random.default_rng(5)
    p, line = _scan(rng, 0.2, _heavy(0.005))
    turn = np.deg2rad(45.0)
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    q = p.copy()
    q[:, :2] = p[:, :2] @ rot.T
    inside = (np.abs(q[:, 0]) < 2.5) & (np.abs(q[:, 1]) < 2.5)
    both = np.vstack([p, q[inside]]), np.concatenate([line, line[inside] + line.max() + 1])
    with pytest.raises(MeasurementError, match="more than one direction.*one pass"):
        measure_depth(*both, POCKET, DepthSettings(ring_mm=1.5))
    assert measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5)).mean_depth()[0] == \
        pytest.approx(0.2, abs=0.003)
    small = np.deg2rad(2.0) * (line % 2)                    # every other line 2° off
    r = p.copy()
    r[:, 0] += np.sin(small) * p[:, 1]
    assert measure_depth(r, line, POCKET, DepthSettings(ring_mm=1.5)).mean_depth()[0] == \
        pytest.approx(0.2, abs=0.003)


def _shifted(rng, shift: float, depth: float = 0.2, ramp: float = 0.15):
    """Lines along y 0.1 mm apart over a 2 × 2 mm pocket ``depth`` deep whose floor reads
    short within ``ramp`` mm of the walls the lines cross (the line straddling the edge),
    placed ``shift`` mm off along the lines, 20 µm noise: (points (N, 3), line (N,))."""
    pts, line = [], []
    y = np.arange(-2.5, 2.5, 0.02)
    for k, x in enumerate(np.arange(-2.45, 2.46, 0.1)):
        d = depth * np.clip((1.0 - np.abs(y)) / ramp, 0, 1) * (abs(x) < 1.0)
        z = 5.0 + 0.004 * x - d + 0.02 * rng.standard_normal(len(y))
        pts.append(np.column_stack([np.full(len(y), x), y + shift, z]))
        line.append(np.full(len(y), k))
    return np.vstack(pts), np.concatenate(line)


def test_a_pockets_depth_is_measured_on_the_walls_the_lines_cross():
    """A scan placed 0.2 mm off along its lines: unregistered, the floor kept clear of one
    crossed wall as the scan places it lies within 0.1 mm of the wall itself, where the line
    straddling the edge reads short (2–4 µm on the mean); the pocket's depth registers by
    default (the shift found, the mean within 1 µm)."""
    errs = []
    for seed in (0, 1):
        p, line = _shifted(np.random.default_rng(seed), 0.2)
        dm = measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5))
        off = measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5, register_mm=0.0))
        assert abs(dm.shift_mm - 0.2) < 0.02
        errs.append((dm.mean_depth()[0] - 0.2, off.mean_depth()[0] - 0.2))
    on, off = np.mean(errs, axis=0)
    assert abs(on) < 0.001 and off < -0.0015


def _tapered(rng, depth: float, taper: float, noise: float = 0.01):
    """:func:`_scan`'s lines over a pocket ``depth`` deep whose walls slope from the outline
    down to the floor over ``taper`` mm, Gaussian noise ``noise`` mm."""
    p, line = _scan(rng, 0.0, lambda rng, n: noise * rng.standard_normal(n))
    inward = np.minimum(1.0 - np.abs(p[:, 0]), 1.0 - np.abs(p[:, 1]))
    p[:, 2] -= depth * np.clip(inward / taper, 0.0, 1.0)
    return p, line


def test_points_on_the_floor_that_cannot_be_floor_are_left_out_and_counted():
    """One line 0.15 mm inside a wall reads 3 mm above the top over its floor (the simulated
    plate's 0.5 mm pocket, walls sloping over 0.3 mm: the camera took another light path for
    the line): kept, its line's term spread it over the floor (−153 ± 169 µm); left out, the
    depth is the floor's and the points left out are counted."""
    rng = np.random.default_rng(5)
    p, line = _tapered(rng, 0.5, 0.03)
    ghost = (np.abs(p[:, 0] + 0.85) < 0.02) & (np.abs(p[:, 1]) < 0.9)
    p[ghost, 2] += 3.5
    dm = measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5))
    mean, sem = dm.mean_depth()
    assert abs(mean - 0.5) < max(3 * sem, 0.002)
    assert dm.not_floor >= ghost.sum() - 2


def test_the_floor_begins_where_the_sloping_wall_ends_as_measured():
    """Walls sloping over 0.3 mm into a 0.2 mm pocket, 30 µm noise: the wall's points, at a
    fraction of the floor's depth, pass the zones set by the depth around them and read the
    pocket 16–19 µm short (σ 7–8 µm); the floor begins where the profile across the wall
    reaches it (a scan with straight walls keeps its floor points)."""
    for seed in (6, 8):
        p, line = _tapered(np.random.default_rng(seed), 0.2, 0.3, 0.03)
        mean, sem = measure_depth(p, line, POCKET, DepthSettings(ring_mm=1.5)).mean_depth()
        assert abs(mean - 0.2) < 0.006 and sem < 0.003
    straight = measure_depth(*_tapered(np.random.default_rng(6), 0.2, 0.03, 0.03), POCKET,
                             DepthSettings(ring_mm=1.5))
    assert abs(straight.mean_depth()[0] - 0.2) < 0.002
