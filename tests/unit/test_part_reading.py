"""Production's read-back check: a marked part whose code is not the plan, or lies farther
from its planned place than the recipe's ``read.offset_tolerance_mm``, is logged with the
reason (never passed silently); the tolerance is the recipe's, 0.1 mm when absent."""

import json

import numpy as np
import pytest

from insitu.errors import FormatError
from insitu.formats.production_log import read_log
from insitu.formats.recipe import Recipe, RecipeScan, read_recipe, write_recipe
from insitu.marking import Placement
from insitu.marking.modes import PROJECTIONS
from insitu.services import production
from insitu.services.locate import Located
from insitu.services.part_reading import PartReading, reading_fault
from insitu.services.station import connect


def test_a_mark_beyond_the_tolerance_or_not_the_plan_fails_with_one_line():
    far = reading_fault(PartReading("00001", True, "C", 0.304), 0.1)
    assert "0.304 mm from its planned place" in far and "offset_tolerance_mm 0.1" in far
    assert "\n" not in far
    assert reading_fault(PartReading("00001", True, "C", 0.0966), 0.1) is None
    assert reading_fault(PartReading("00001", True, "C", 0.304), 0.35) is None
    assert "no code read" in reading_fault(PartReading(None, False, None, 0.02), 0.1)
    assert "read '00007'" in reading_fault(PartReading("00007", False, "A", 0.02), 0.1)
    assert reading_fault(PartReading(), 0.1) is None           # nothing was read back


def test_the_recipes_read_tolerance_reads_back_and_is_checked(tmp_path):
    ref = tmp_path / "ref.ply"
    ref.write_bytes(b"")                        # named by the recipe, not read here
    r = Recipe(ref, "cloud", (Placement("text:A;size=2", (0.0, 0.0), 4.0, 0.0),))
    path = tmp_path / "r.json"
    write_recipe(path, r)
    assert json.loads(path.read_text())["read"] == {"offset_tolerance_mm": 0.1}
    write_recipe(path, Recipe(ref, "cloud", r.placements, read_tolerance_mm=0.25))
    assert read_recipe(path, Placement, PROJECTIONS).read_tolerance_mm == 0.25
    raw = json.loads(path.read_text())
    del raw["read"]
    path.write_text(json.dumps(raw))
    assert read_recipe(path, Placement, PROJECTIONS).read_tolerance_mm == 0.1
    raw["read"] = {"offset_tolerance_mm": -1}
    path.write_text(json.dumps(raw))
    with pytest.raises(FormatError, match="read.offset_tolerance_mm"):
        read_recipe(path, Placement, PROJECTIONS)


def test_produce_logs_a_part_read_back_off_its_place_with_the_reason(tmp_path):
    """The read-back puts the part's mark 0.30 mm off its place (as seed 8's uncorrected head
    did): the part is logged marked, with the reason."""
    (tmp_path / "ref.ply").write_bytes(b"")     # not read: ``where`` locates the part
    with connect(None, "step-block", 0, 4) as station:
        recipe = Recipe(tmp_path / "ref.ply", "cloud", (
            Placement('text:"A";size=2', (0.0, -30.0), 4.0, 10.0),), scan=RecipeScan(
                margin_mm=4.0, spacing_mm=1.0), workpiece="step-block")
        where = lambda cloud, room_light=None: Located(np.eye(4), 1.0, 0.0)  # noqa: E731
        run = production.Production(recipe, station, tmp_path / "run.jsonl", 1, where,
                                    lambda *_: PartReading("A", True, "B", 0.304))
        production.produce(run)
    (rec,) = read_log(tmp_path / "run.jsonl")
    assert rec.outcome == "marked" and rec.offset_mm == 0.304, rec.error
    assert "0.304 mm from its planned place" in rec.error
