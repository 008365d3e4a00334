"""The pocket plate: a blank with four square pockets 0.05, 0.1, 0.2 and 0.5 mm deep cut
straight into it (walls tapered over 30 µm), in a row along its x, centred on its origin —
the part the plate benchmark (benchmarks/engrave_plate.py) and ``insitu sim record scan
--workpiece pocket-plate`` (2 mm pockets at x = −7.5, −2.5, 2.5, 7.5) measure. Each pocket's
truth (:func:`pocket_truth`): its outline in the world and its true mean depth over the floor
0.2 mm inside its walls."""

from __future__ import annotations

import numpy as np

from insitu.sim.ablation import ABLATION, Engraving
from insitu.sim.workpieces import to_world

PLATES = {"pocket-plate": "blank-stainless"}
"""The plates' names → the blank they are cut into."""
DEPTHS = (0.05, 0.1, 0.2, 0.5)
SIZE_MM = 2.0
"""The pockets' side, mm (the benchmark's ``--size``; the issue's pockets are 6 mm)."""
GAP_MM = 3.0
"""Between two pockets' walls, mm: each pocket's top ring (1.5 mm) clear of the next one."""
TAPER_MM = 0.03
TRUTH_INSET_MM = 0.2
"""The true mean depth is taken this far inside the walls (beyond their taper), or as far as
they slope where that is wider."""


def centres_x(size_mm: float = SIZE_MM) -> np.ndarray:
    """(4,) the pockets' centres' x, mm, for pockets ``size_mm`` wide: :data:`GAP_MM` between
    them, the plate centred on x = 0 (2 mm: −7.5, −2.5, 2.5, 7.5)."""
    return (np.arange(len(DEPTHS)) - (len(DEPTHS) - 1) / 2) * (size_mm + GAP_MM)


def cut_plate(world, taper_mm: float = TAPER_MM, size_mm: float = SIZE_MM) -> None:
    """The four pockets, ``size_mm`` square, straight into part 0 of ``world`` (in the
    part's own frame, so they move with its pose); ``world.plate`` keeps their side."""
    part = world.parts[0]
    eng = Engraving(ABLATION[part.name], seed=1)
    half, cxs = size_mm / 2, centres_x(size_mm)
    eng.cover(part, np.array([cxs.min() - half, -half]), np.array([cxs.max() + half, half]))
    xs, ys = eng.nodes()
    removed = np.zeros((len(ys), len(xs)))
    for cx, depth in zip(cxs, DEPTHS):
        d = np.minimum(np.clip(half - np.abs(xs - cx)[None, :], 0, None),
                       np.clip(half - np.abs(ys)[:, None], 0, None))
        removed = np.maximum(removed, np.minimum(d / taper_mm, 1.0) * depth)
    eng.removed = removed.astype(np.float32)
    eng.version += 1
    world.engravings[0] = eng
    world.plate = size_mm
    world.invalidate()


def pocket_truth(world, taper_mm: float = TAPER_MM) -> list[dict]:
    """Each pocket of the plate cut in part 0 of ``world`` (:func:`cut_plate`): ``depth_mm``
    (as cut), ``corners`` (4, 2) world x, y mm of its outline, ``box`` [x0, y0, x1, y1] world
    mm (its bounding box: the outline itself when the part is not turned) and
    ``true_mean_mm``, the world's removed depth (``SimWorld.true_depth``) averaged over
    41 × 41 points of its floor :data:`TRUTH_INSET_MM` inside the walls, or ``taper_mm`` (how
    far they slope, :func:`cut_plate`) where that is wider: a pocket's depth is its floor's,
    the wall is not the floor."""
    part, half = world.parts[0], world.plate / 2
    inset = max(TRUTH_INSET_MM, taper_mm)
    out = []
    for cx, depth in zip(centres_x(world.plate), DEPTHS):
        g = np.meshgrid(np.linspace(cx - half + inset, cx + half - inset, 41),
                        np.linspace(-half + inset, half - inset, 41))
        truth = float(world.true_depth(*to_world(part, *g)).mean())
        cu = np.array([cx - half, cx + half, cx + half, cx - half])
        cv = np.array([-half, -half, half, half])
        corners = np.column_stack(to_world(part, cu, cv))
        out.append({"depth_mm": depth, "corners": np.round(corners, 6).tolist(),
                    "box": np.round([*corners.min(0), *corners.max(0)], 6).tolist(),
                    "true_mean_mm": truth})
    return out
