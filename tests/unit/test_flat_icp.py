"""The flat ICP: a fit whose pairs flip between two sets ends where its iterations would
have ended, without running them."""

import numpy as np
import pytest

from insitu.locate import flat_icp


def _flipping(monkeypatch, calls):
    """Pairs that flip: every point is paired with the plane x = +1 while the points' mean x
    is below 0, else with x = −1 — the fit jumps between the two for ever."""

    def residuals(src, tree, normals, targets, reach_mm):
        calls.append(1)
        plane = 1.0 if src[:, 0].mean() < 0 else -1.0
        return np.ones(len(src), bool), np.zeros(len(src), int), src[:, 0] - plane

    monkeypatch.setattr(flat_icp, "residuals", residuals)


@pytest.mark.parametrize("iterations", [10, 11])
def test_a_two_pose_cycle_ends_on_the_pose_its_iterations_end_on(monkeypatch, iterations):
    grid = np.stack(np.meshgrid(np.arange(-2.0, 2.5), np.arange(-2.0, 2.5)), -1).reshape(-1, 2)
    src = np.column_stack([grid, np.zeros(len(grid))])
    normals = np.array([[1.0, 0.0, 0.0]])
    calls: list = []
    _flipping(monkeypatch, calls)
    start = (0.0, np.array([-1.0, 0.0, 0.0]))
    got = flat_icp.icp_flat(src, normals, normals, None, start, (1.0,), iterations,
                            inlier_mm=10.0).pose
    shortcut = len(calls) - 1                       # the last call is the fit's score
    monkeypatch.setattr(flat_icp, "_same", lambda a, b: False)
    calls.clear()
    full = flat_icp.icp_flat(src, normals, normals, None, start, (1.0,), iterations,
                             inlier_mm=10.0).pose
    assert len(calls) - 1 == iterations and shortcut == 2       # it stopped at the cycle
    assert got[1][0] == pytest.approx(full[1][0], abs=1e-9) and got[0] == full[0]
    assert got[1][0] == pytest.approx(1.0 if iterations % 2 else -1.0)
