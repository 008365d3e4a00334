"""A scan's height image (:mod:`insitu.locate.height_image`): lines 1 mm apart over a sloped
top (another renderer's recording, every second line) splatted without stripes or terraces
that the rough outline would take for edges."""

import numpy as np

from insitu.locate.height_image import line_gap_mm, splat_image
from insitu.locate.image_edges import outline


def _scan(gap_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """A 16 × 16 mm top rising 0.9 mm a mm along x (z = 8 + 0.9 x) on a table at 0, scanned
    by lines along y ``gap_mm`` apart, a point every 0.09 mm: (points (N, 3), lines (N,))."""
    xs = np.arange(-12.0, 12.0 + 1e-9, gap_mm) + 0.3
    ys = np.arange(-12.0, 12.0, 0.09)
    x, y = np.meshgrid(xs, ys, indexing="ij")
    on = (np.abs(x) <= 8.0) & (np.abs(y) <= 8.0)
    z = np.where(on, 8.0 + 0.9 * x, 0.0)
    lines = np.repeat(np.arange(len(xs)), len(ys))
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()]), lines


def test_lines_a_millimetre_apart_give_a_top_without_false_edges():
    """The top is measured everywhere between its lines (none of it left at the table's
    height) and rises smoothly: the rough outline lies on its four sides only."""
    pts, lines = _scan(1.0)
    assert abs(line_gap_mm(pts, lines) - 1.0) < 0.01
    part = pts[pts[:, 2] > 0.5]
    heights = splat_image(pts, part, 0.0, lines=lines)
    c, r = np.meshgrid(np.arange(heights.z.shape[1]), np.arange(heights.z.shape[0]))
    x, y = heights.x0_mm + c * heights.px_mm, heights.y0_mm + r * heights.px_mm
    inner = (np.abs(x) < 7.0) & (np.abs(y) < 7.0)
    assert heights.z[inner].min() > 1.0
    assert np.abs(heights.z[inner] - (8.0 + 0.9 * x[inner])).max() < 0.1
    edges = outline(heights).points[:, :2]
    off_side = np.minimum(np.abs(np.abs(edges[:, 0]) - 8.0), np.abs(np.abs(edges[:, 1]) - 8.0))
    assert len(edges) > 100 and np.percentile(off_side, 99) < 0.6, np.percentile(off_side, 99)
