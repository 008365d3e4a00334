"""Engraving where walls stand close: a slot narrower than the floor can be measured at its
depth (the floor beside the wall the camera faces reads short) and a pocket whose walls hide
part of its floor from the camera. Scored by the simulator's truth: never over-burnt, and the
cells the measurement could not vouch for are named."""

import numpy as np
import pytest
import shapely

from insitu.marking import Placement
from insitu.marking.engrave_depth import (
    HIDDEN,
    MEASURED,
    DepthSettings,
    Outline,
    measure_depth,
)
from insitu.marking.engrave_plan import CellHistory, learn, plan_round
from insitu.marking.engrave_walls import viewpoints
from insitu.services.engrave import NO_HEIGHT_CAL, EngraveRequest, engrave
from insitu.services.engrave_report import depth_picture
from insitu.services.pocket import DEPTH_CENTRES
from insitu.services.scan import scan_live
from insitu.services.station import connect
from insitu.sim.ablation import ABLATION, Engraving
from insitu.vision.extract import CentreSettings

TOLERANCE = 0.010        # the mean tolerance; the deepest point within 0.025


def _rect(tmp_path, w: float, h: float):
    path = tmp_path / f"rect-{w:g}x{h:g}.svg"
    path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}mm" height="{h}mm" '
                    f'viewBox="0 0 {w} {h}"><rect width="{w}" height="{h}"/></svg>')
    return str(path)


@pytest.fixture(scope="module")
def top_cloud():
    """The blank's top, scanned coarsely once (the focus and the pocket's top)."""
    with connect(None, "blank-stainless", 0) as station:
        return scan_live(station, 1.0, (-2.5, 2.5, -2.5, 2.5), room_light=False).cloud


def _truth(world, region) -> np.ndarray:
    """The true depth over the floor beyond the walls' 0.2 mm taper, every 0.025 mm."""
    floor = region.buffer(-0.2)
    x0, y0, x1, y1 = floor.bounds
    g = np.meshgrid(np.arange(x0, x1, 0.025), np.arange(y0, y1, 0.025))
    inside = shapely.contains_xy(floor, *g)
    return world.true_depth(g[0][inside], g[1][inside])


def test_a_narrow_slot_is_not_over_burnt_and_its_unmeasured_cells_are_named(tmp_path,
                                                                              top_cloud):
    target = 0.2
    req = EngraveRequest(tmp_path / "report", Placement(_rect(tmp_path, 0.8, 1.2), (0.0, 0.0),
                                                        None, 0.0),
                         top_cloud, target, rescan_every=25,
                         settings=DepthSettings(ring_mm=0.8))
    notes: list[str] = []
    with connect(None, "blank-stainless", 0) as station:
        outcome = engrave(station, req, notify=notes.append)
        truth = _truth(station.world, shapely.box(-0.4, -0.6, 0.4, 0.6))
    rec = outcome.record
    assert truth.mean() <= target + TOLERANCE, (truth.mean(), notes)
    assert truth.max() <= target + 0.025, (truth.max(), notes)
    # its floor, crossed by three lines beyond the walls' bias zone, was never measured: the
    # passes stopped where the table's rate at its highest likely says the depth is reached
    assert all(m["cells"]["measured"] == 0 for m in rec.measures)
    assert rec.outcome["model_cells"] > 0 and rec.state in ("done", "held")
    warning = [n for n in notes if n.startswith("warning:") and n != NO_HEIGHT_CAL]
    assert warning == [f"warning: {rec.outcome['model_cells']} cells of {req.placement.pattern}"
                       " not measured: their depth follows the model, not the measurement"]
    print(f"slot: mean {truth.mean():.4f} deepest {truth.max():.4f}", notes)


def _cut(world, w: float, h: float, depth: float, taper_mm: float = 0.03) -> None:
    """A w × h mm pocket ``depth`` deep straight into the blank (walls tapered): what many
    passes leave, without marking them."""
    part = world.parts[0]
    eng = Engraving(ABLATION[part.name], seed=1)
    eng.cover(part, np.array([-w / 2, -h / 2]), np.array([w / 2, h / 2]))
    xs, ys = eng.nodes()
    d = np.minimum(np.clip(w / 2 - np.abs(xs)[None, :], 0, None),
                   np.clip(h / 2 - np.abs(ys)[:, None], 0, None))
    eng.removed = (np.minimum(d / taper_mm, 1.0) * depth).astype(np.float32)
    eng.version += 1
    world.engravings[0] = eng
    world.invalidate()


def test_a_pocket_whose_wall_hides_its_floor_reports_the_hidden_cells_never_over_burnt(
        tmp_path):
    """A 2 × 3 mm pocket 0.45 mm deep (100 passes at 4.5 µm) on its way to 0.5 mm: the camera,
    ~150 mm off to −x at 330 mm, cannot see 0.2 mm of the floor along the −x wall. Those cells
    are reported hidden (and drawn so), the planner gives them no pass beyond what their
    highest likely rate allows, and the cells it sees go on to the depth."""
    target, region = 0.5, shapely.box(-1.0, -1.5, 1.0, 1.5)
    s = DepthSettings(ring_mm=1.0)
    with connect(None, "blank-stainless", 0) as station:
        _cut(station.world, 2.0, 3.0, 0.45)
        scan = scan_live(station, 0.1, (-1.5, 1.5, -2.5, 2.5), room_light=False,
                         centres=CentreSettings(**DEPTH_CENTRES))
        outline = Outline(region, s.ring_mm + s.cell_mm)
        cells = outline.cells(s.cell_mm)
        h = CellHistory.start(cells.shape, 0.0045)
        h.given(np.where(cells.inside, 100.0, 0.0))
        dm = measure_depth(scan.cloud.points, scan.cloud.attributes["line"], region, s,
                           outline, cells, viewpoints(station.rig), h.estimate)
    gx, _ = cells.centres()
    hidden = dm.state == HIDDEN
    assert hidden.sum() >= 8 and np.all(gx[hidden] < -0.5)          # along the −x wall
    assert dm.count(MEASURED) >= 20
    assert abs(dm.mean_depth()[0] - 0.45) <= 0.015      # seen: −10 µm, 2 mm wide, 0.45 deep
    learn(h, dm, 0.0045)
    for _ in range(10):                                 # rounds on the same belief
        plan = plan_round(h, dm.state, target, rescan_every=25)
        if plan.layers == 0:
            break
        h.given(plan.equivalent())
    # never over-burnt: no pass to a hidden cell beyond what its highest likely rate (15 %
    # faster) allows; the seen ones were planned to the depth; the short hidden ones held
    rate_hi = 1.15 * h.rate[hidden]
    assert np.all(h.passes[hidden] <= np.maximum(100.0, target / rate_hi + 1e-9))
    seen = dm.state == MEASURED
    assert np.all(np.abs(h.passes[seen] * h.rate[seen] - target) <= 0.6 * h.rate[seen])
    assert np.array_equal(plan.held, hidden & (h.passes * h.rate < target - 0.5 * h.rate))
    assert plan.held.any()
    depth_picture(tmp_path / "map.png", dm, target, "hidden")
    assert (tmp_path / "map.png").stat().st_size > 0
