"""The 3-D check across lines (insitu.reconstruct.consistency): wrong lines go, edges stay."""

import numpy as np

from insitu.reconstruct.consistency import cross_line_inliers

SPACING = 0.5


def _scan(rng, sigma=0.02):
    """Lines along y every 0.5 mm over x −10…10: a 10 mm block on x < 2.1 (its wall parallel to
    the lines), a 3 mm step across the lines at y = 0, noise ``sigma``."""
    xs = np.arange(-10.0, 10.01, SPACING)
    y = np.arange(-20.0, 20.0, 0.08)
    pts, line = [], []
    for i, x in enumerate(xs):
        z = np.where(x < 2.1, 10.0, 0.0) + np.where(y > 0, 3.0, 0.0)
        pts.append(np.column_stack([np.full_like(y, x), y, z + rng.normal(0, sigma, len(y))]))
        line.append(np.full(len(y), i))
    return np.vstack(pts), np.concatenate(line)


def test_a_ghost_on_one_or_two_lines_is_removed_and_edges_are_kept():
    rng = np.random.default_rng(1)
    pts, line = _scan(rng)
    ghost = ((line == 30) | (line == 31)) & (pts[:, 1] > 5) & (pts[:, 1] < 9)   # two lines
    lone = (line == 10) & (pts[:, 1] > -9) & (pts[:, 1] < -6)                  # one line
    pts[ghost, 2] -= 5.0
    pts[lone, 2] += 0.4                            # 20 sigma: a peak of the wrong level
    keep = cross_line_inliers(pts, line)
    assert not keep[ghost].any() and not keep[lone].any()
    good = ~(ghost | lone)
    assert keep[good].mean() > 0.995
    wall = good & (np.abs(pts[:, 0] - 2.0) < 0.01)      # the last line on the block's top
    floor = good & (np.abs(pts[:, 0] - 2.5) < 0.01)     # the first beside it
    assert keep[wall].mean() > 0.99 and keep[floor].mean() > 0.99
    step = good & (np.abs(pts[:, 1]) < 0.2)             # across the step at y = 0
    assert keep[step].mean() > 0.9


def test_too_few_lines_to_judge_keeps_everything():
    rng = np.random.default_rng(2)
    pts, line = _scan(rng)
    two = line < 2
    pts2, line2 = pts[two].copy(), line[two]
    pts2[:50, 2] += 5.0
    assert cross_line_inliers(pts2, line2).all()


def test_a_line_beside_a_wall_with_no_second_line_on_its_side_is_kept():
    """The floor beside the block seen by one line only: nothing says the surface runs on
    across it, so nothing removes it (a wall, not a ghost)."""
    rng = np.random.default_rng(3)
    pts, line = _scan(rng)
    keep_lines = pts[:, 0] <= 2.51
    pts, line = pts[keep_lines], line[keep_lines]
    keep = cross_line_inliers(pts, line)
    floor = np.abs(pts[:, 0] - 2.5) < 0.01
    assert floor.any() and keep[floor].mean() > 0.99
