"""The simulated pocket plate (``--workpiece pocket-plate``): its four pockets cut in the
part's own frame, so they move with its pose; its truth (each pocket's outline and true mean
depth) in the world's truth; the plate benchmark cuts the same plate."""

import numpy as np

from benchmark_module import benchmark
from insitu.sim import pocket_plate
from insitu.sim.world import sim_world


def test_the_pockets_move_with_the_plates_pose_and_the_truth_names_them():
    world = sim_world("pocket-plate", pose=(1.0, 2.0, 30.0))
    pockets = world.truth()["pockets"]
    assert [p["depth_mm"] for p in pockets] == list(pocket_plate.DEPTHS)
    for p in pockets:
        corners = np.array(p["corners"])
        centre = corners.mean(axis=0)
        edge = np.linalg.norm(corners[1] - corners[0])
        assert np.isclose(edge, pocket_plate.SIZE_MM)
        inside = world.true_depth(*(centre + 0.9 * (corners - centre)).T)
        outside = world.true_depth(*(centre + 1.1 * (corners - centre)).T)
        assert np.allclose(inside, p["depth_mm"], atol=1e-6) and np.all(outside == 0)
        assert abs(p["true_mean_mm"] - p["depth_mm"]) < 1e-6
        assert np.allclose(p["box"], [*corners.min(0), *corners.max(0)])


def test_a_blank_has_no_pockets_in_its_truth():
    world = sim_world("blank-stainless")
    assert "pockets" not in world.truth() and world.true_depth(2.5, 0.0) == 0
    world = sim_world("pocket-plate")
    world.clear_table()
    assert "pockets" not in world.truth()


def test_the_plate_benchmark_measures_the_simulators_plate():
    ep = benchmark("engrave_plate")
    assert ep.cut_plate is pocket_plate.cut_plate and ep.centres_x is pocket_plate.centres_x


def test_the_truth_of_a_plate_whose_walls_slope_wide_is_its_floor_not_its_wall():
    """Walls sloping over 0.3 mm: the truth is the floor's depth as cut (taken 0.2 mm inside
    the walls it would average 0.1 mm of wall, 2.8–27.8 µm shallow)."""
    world = sim_world("blank-stainless")
    pocket_plate.cut_plate(world, taper_mm=0.3)
    truth = [p["true_mean_mm"] for p in pocket_plate.pocket_truth(world, taper_mm=0.3)]
    assert np.allclose(truth, pocket_plate.DEPTHS, atol=1e-6)
