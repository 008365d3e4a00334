"""Is a scan fit to be a recipe's reference: the part's whole top measured, with a margin of
table around it (synthetic scans: a 40 × 30 × 10 mm block on a table, lines 1 mm apart)."""

import numpy as np
import pytest

from insitu.errors import MeasurementError
from insitu.services.reference_check import check_reference


def scan(x=(-40.0, 40.0), y=(-30.0, 30.0), spacing=1.0, missing=None):
    """Lines along x every ``spacing`` mm over the box ``x`` × ``y``: the table at z = 0, the
    block (|x| ≤ 20, |y| ≤ 15) at z = 10; ``missing``: (x0, x1, y0, y1), a hole in the
    block's top where nothing was measured (a shadow, a dark patch)."""
    ys = np.arange(y[0], y[1] + 1e-9, spacing)
    xs = np.arange(x[0], x[1] + 1e-9, 0.2)
    gx, gy = np.meshgrid(xs, ys)
    line = np.broadcast_to(np.arange(len(ys))[:, None], gx.shape)
    block = (np.abs(gx) <= 20) & (np.abs(gy) <= 15)
    z = np.where(block, 10.0, 0.0)
    keep = np.ones_like(block)
    if missing is not None:
        x0, x1, y0, y1 = missing
        keep &= ~(block & (gx > x0) & (gx < x1) & (gy > y0) & (gy < y1))
    pts = np.c_[gx[keep], gy[keep], z[keep]]
    return pts, line[keep]


def test_a_whole_part_with_a_margin_is_a_reference():
    c = check_reference(*scan())
    assert c.level == "ok" and c.coverage > 0.95 and c.cut == ()
    assert c.spacing_mm == pytest.approx(1.0, abs=0.05)


def test_a_part_cut_by_the_scans_edge_is_refused():
    c = check_reference(*scan(x=(-40.0, 15.0)))
    assert c.level == "refused" and c.cut == ("x+",)
    assert "reaches the scan's edge at x+" in c.text


def test_a_top_measured_in_part_is_a_warning_then_a_refusal():
    warn = check_reference(*scan(missing=(-5.0, 5.0, -6.0, 6.0)))       # 10 % of the top
    assert warn.level == "warning" and 0.8 < warn.coverage < 0.95
    refused = check_reference(*scan(missing=(-12.0, 12.0, -9.0, 9.0)))  # 36 %
    assert refused.level == "refused" and refused.coverage < 0.8
    assert f"{refused.coverage:.0%} of the part's top" in refused.text


def test_no_part_on_the_table_is_a_measurement_error():
    pts, line = scan()
    with pytest.raises(MeasurementError, match="no part above the table"):
        check_reference(pts[pts[:, 2] < 1], line[pts[:, 2] < 1])
