"""Why the edge step finds no fit: the direction the edges found leave free
(:func:`insitu.locate.edge_align.unheld`), and the turn and shift across it fitted alone
(``align_edges(free=…)``), on the step block's reference (part frame, mm)."""

import numpy as np
import pytest

from insitu.locate.edge_align import align_edges
from insitu.locate.reference import reference_from_mesh
from insitu.locate.unheld import unheld
from insitu.sim.workpieces import make_workpiece


@pytest.fixture(scope="module")
def heights():
    mesh = make_workpiece("step-block")
    return reference_from_mesh(mesh.vertices, mesh.triangles, "step-block").heights


def _samples(xs, y_edge, z, facing, inside=0.05):
    """Edge samples on a step edge across x at ``y_edge`` (the top at height ``z`` drops
    toward ``facing`` = ±1 along y), ``inside`` mm in from it."""
    e = np.column_stack([xs, np.full(len(xs), y_edge - facing * inside), np.full(len(xs), z)])
    return e, np.tile([0.0, float(facing)], (len(xs), 1))


def test_edges_facing_one_way_leave_the_other_direction_free(heights):
    xs = np.linspace(-8, 8, 12)
    e1, u1 = _samples(xs, -20.0, 5.0, -1)       # the 5 mm step down to 3 mm at y = -20
    e2, u2 = _samples(xs, 40.0, 15.0, +1)       # the 15 mm step's far end
    e, u = np.vstack([e1, e2]), np.vstack([u1, u2])
    found, free = unheld(heights, e, u)
    assert found == 24 and free is not None and abs(free[0]) > 0.99     # free along x
    # the turn and y alone: samples moved 0.2 mm along y and turned 0.1° are brought back
    a = np.radians(0.1)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    moved = np.column_stack([e[:, :2] @ R.T + [0.0, 0.2], e[:, 2]])
    fit = align_edges(heights, moved, u @ R.T, free=free)
    assert fit is not None and abs(np.degrees(fit.angle_rad) + 0.1) < 0.01
    back = moved[:, :2] @ np.array([[np.cos(fit.angle_rad), -np.sin(fit.angle_rad)],
                                    [np.sin(fit.angle_rad), np.cos(fit.angle_rad)]]).T
    assert np.abs((back + fit.shift_mm)[:, 1] - e[:, 1]).max() < 0.02
    assert align_edges(heights, moved, u @ R.T) is None     # without free: no fit


def test_two_faces_leave_their_bisector_free_and_a_third_holds_it(heights):
    """Insetting a corner's two edges alike moves it along their bisector: two faces alone
    do not place the part; a third does."""
    e1, u1 = _samples(np.linspace(-8, 8, 12), -20.0, 5.0, -1)      # faces -y
    side = np.column_stack([np.full(12, 9.95), np.linspace(22, 38, 12), np.full(12, 15.0)])
    e, u = np.vstack([e1, side]), np.vstack([u1, np.tile([1.0, 0.0], (12, 1))])  # and +x
    found, free = unheld(heights, e, u)
    assert found == 24 and abs(free @ np.array([1.0, -1.0])) / np.sqrt(2) > 0.99
    assert align_edges(heights, e, u) is None
    e3, u3 = _samples(np.linspace(-8, 8, 12), 40.0, 15.0, +1)       # and +y
    e, u = np.vstack([e, e3]), np.vstack([u, u3])
    moved = e + [0.1, -0.15, 0.0]
    fit = align_edges(heights, moved, u)
    assert fit is not None and np.abs(fit.shift_mm - [-0.1, 0.15]).max() < 0.01
    far = np.column_stack([np.linspace(-5, 5, 10), np.full(10, -30.0), np.full(10, 3.0)])
    assert unheld(heights, far, np.tile([0.0, 1.0], (10, 1))) == (0, None)
