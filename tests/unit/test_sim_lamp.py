"""The simulator's room light from a lamp (``Optics.lamp_share``, ``lamp_deg``): the part
casts its shadow on the table away from the lamp, and the walls facing the lamp are lit —
what locate's benchmarks vary the room light with."""

from dataclasses import replace

import numpy as np

from insitu.sim.marks import RoomLightView
from insitu.sim.rig import default_rig
from insitu.sim.scene import Scene
from insitu.sim.workpieces import make_workpiece


def _shade_at(view, rig, xyz):
    """The room light of the pixel that sees world point ``xyz``."""
    u, v = np.rint(rig.camera.project(np.array([xyz]))[0]).astype(int)
    index = np.cumsum(view.hit) - 1
    return float(view.shade[index[v * view.shape[1] + u]])


def test_a_lamp_casts_the_blocks_shadow_away_from_it():
    rig = default_rig(seed=0, binning=8)
    scene = Scene([make_workpiece("table"), make_workpiece("step-block")])
    lamp = replace(rig, optics=replace(rig.optics, lamp_share=0.9, lamp_deg=(0.0, 30.0)))
    diffuse, lit = RoomLightView(rig, scene, ideal=True), RoomLightView(lamp, scene, ideal=True)
    # the 15 mm top stands at y 20 … 40: at 30° its shadow reaches 26 mm toward −x
    away, toward = (-15.0, 30.0, 0.0), (30.0, 30.0, 0.0)
    assert np.isclose(_shade_at(diffuse, rig, away), _shade_at(diffuse, rig, toward), rtol=0.05)
    assert _shade_at(lit, lamp, away) < 0.3 * _shade_at(lit, lamp, toward)
