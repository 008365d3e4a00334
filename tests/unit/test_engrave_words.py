"""The Engrave dock's words (no Qt): a depth map's summary (mean, the 95 % band, the cells
hidden and not measured counted) and how an engraving ended, from its record."""

from pathlib import Path

import numpy as np
import pytest

from insitu.formats.materials import DEFAULT_MATERIALS
from insitu.marking.engrave_depth import (
    HIDDEN,
    MEASURED,
    OUTSIDE,
    UNMEASURED,
    WALL,
    DepthMap,
    PocketCells,
)
from insitu.marking.engrave_record import EngraveAsk, EngraveRecord
from insitu.ui.model.depth_view import DepthSummary
from insitu.ui.model.engrave_words import engrave_rows, verdict


def small_map() -> DepthMap:
    state = np.array([[OUTSIDE, WALL, WALL, OUTSIDE],
                      [HIDDEN, MEASURED, MEASURED, WALL],
                      [UNMEASURED, MEASURED, MEASURED, WALL]], np.int8)
    depth = np.where(state == MEASURED, [[0, 0, 0, 0], [0, 0.19, 0.20, 0], [0, 0.21, 0.22, 0]],
                     np.where(state == WALL, 0.18, np.nan))
    cells = PocketCells(np.zeros(2), 0.25, state != OUTSIDE, np.ones(state.shape))
    floor = np.column_stack([np.zeros(4), np.zeros(4), [0.19, 0.20, 0.21, 0.22]])
    return DepthMap(cells, depth, np.zeros(state.shape), np.ones(state.shape), state, floor,
                    0.001, 0.01)


def test_the_summary_counts_every_state_and_gives_the_band_of_the_measured_cells():
    s = DepthSummary.of(small_map(), target_mm=0.2)
    assert s.counts == {"measured": 4, "wall": 4, "hidden": 1, "unmeasured": 1}
    assert s.mean == pytest.approx(0.205)
    assert s.band == pytest.approx(tuple(np.percentile([0.19, 0.2, 0.21, 0.22], [2.5, 97.5])))
    assert s.p95 == pytest.approx(np.percentile([0.01, 0, 0.01, 0.02], 95))
    text = "\n".join(s.lines())
    assert "mean depth 0.2050 mm" in text and "over 4 measured cells of 10" in text
    assert "1 cells hidden by the walls" in text and "1 cells not measured" in text
    assert "of the target 0.2 mm" in text
    assert "not told apart: connect the rig" in "\n".join(s.lines(rig_known=False))


def record(state: str, **outcome) -> EngraveRecord:
    ask = EngraveAsk(pattern="sq.svg", at_mm=(0, 0), depth_mm=0.2, rescan_every=10,
                     material="stainless-steel")
    return EngraveRecord(state=state, request=ask, material={}, nominal_rate_mm=0.005,
                         cells={}, history={}, layers=40, measures=[{"mean_mm": 0.1987}],
                         outcome=outcome or None)


def test_the_verdict_says_how_it_ended():
    out = Path("/tmp/r")
    assert verdict(record("done"), out).startswith("depth reached: the target 0.2 mm")
    held = verdict(record("held", held_cells=7), out)
    assert held.startswith("stopped at the walls: 7 cells short of 0.2 mm are hidden")
    assert "never over-burnt" in held and "mean depth 0.1987 mm" in held
    stopped = verdict(record("cancelled"), out)
    assert stopped.startswith("stopped (ABORT) after 0 rounds, 40 layers")
    assert "--resume -o /tmp/r" in stopped and "laser is off" in stopped
    assert "a fault" in verdict(record("running"), out, "a fault")
    assert verdict(None, out, "refused: x") == "stopped before anything was marked: refused: x"


def test_the_arming_rows_name_the_depth_material_pen_and_passes():
    m = DEFAULT_MATERIALS.material("beech")
    rows = dict(engrave_rows("sq", 0.2, m, DEFAULT_MATERIALS.laser, 5, 0.1, "sim", None,
                             Path("/tmp/r")))
    rate = m.depth_per_pass_mm(DEFAULT_MATERIALS.laser)
    assert rows["target depth"] == "0.2 mm" and rows["material"].startswith("beech:")
    assert rows["passes"].startswith(f"about {int(np.ceil(0.2 / rate))} at the table's")
    assert "after at most 5 passes" in rows["measured"] and rows["report"] == "/tmp/r"
