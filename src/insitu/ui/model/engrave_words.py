"""An engraving to depth in the operator's words (no Qt): what is armed (as (label, value)
rows for the arming dialog), each re-measure and how it ended (depth reached, cells hidden by
the walls, stopped) from its record (:mod:`insitu.marking.engrave_record`)."""

from __future__ import annotations

import math
from pathlib import Path

from insitu.formats.materials import LaserSource, Material
from insitu.marking.engrave_record import EngraveRecord
from insitu.ui.model.arming import rig_text


def engrave_rows(pattern: str, depth_mm: float, material: Material, laser: LaserSource,
                 rescan_every: int, spacing_mm: float, station_text: str,
                 planned_on: dict | None, report_dir: Path) -> list[tuple[str, str]]:
    """The arming summary of an engraving of ``pattern`` to ``depth_mm`` in ``material``."""
    pen = material.pen
    rate = material.depth_per_pass_mm(laser)
    passes = (f"about {math.ceil(depth_mm / rate)} at the table's {rate * 1e3:.2f} µm per "
              "pass (the rate is learnt from the first measurement)" if rate > 0 else
              "none: the pen stays below the material's ablation threshold")
    return [("pattern", pattern), ("target depth", f"{depth_mm:g} mm"),
            ("material", f"{material.name}: {material.description}"),
            ("pen", f"{pen.name}: {pen.power_pct:g} %, {pen.frequency_khz:g} kHz, mark "
                    f"{pen.mark_speed_mm_s:g} mm/s, hatch {material.hatch_mm:g} mm"),
            ("passes", passes),
            ("measured", f"a scan of the pocket (lines {spacing_mm:g} mm apart) after at most "
                         f"{rescan_every} passes; cells at depth get no more"),
            ("planned on", rig_text(planned_on)), ("station", station_text),
            ("report", str(report_dir))]


def measure_line(m: dict) -> str:
    """One re-measure (an entry of the record's ``measures``) in words."""
    rate = m.get("rate_mm")
    return (f"after round {m['round']}: {m['at_depth']} cells at depth, {m['short']} short, "
            f"{m['over']} over" + (f"; {rate * 1e3:.2f} µm per pass learnt" if rate else ""))


def verdict(record: EngraveRecord | None, report_dir: Path, error: str | None = None) -> str:
    """How the engraving ended, in words: depth reached, stopped at cells the walls hide,
    or stopped (ABORT, a fault: ``error``), with where its record is."""
    if record is None:
        return f"stopped before anything was marked: {error}" if error else "not started"
    target = record.request.depth_mm
    m = record.measures[-1] if record.measures else None
    done = (f"{len(record.rounds)} rounds, {record.layers} layers"
            + (f", mean depth {m['mean_mm']:.4f} mm" if m and m.get("mean_mm") is not None
               else ""))
    if record.state == "done":
        return (f"depth reached: the target {target:g} mm within half a pass in every cell "
                f"the camera sees ({done})")
    if record.state == "held":
        held = (record.outcome or {}).get("held_cells", 0)
        return (f"stopped at the walls: {held} cells short of {target:g} mm are hidden by the "
                f"walls from the camera, left as they are, never over-burnt ({done})")
    why = error or ("ABORT" if record.state == "cancelled" else record.state)
    return (f"stopped ({why}) after {done}; the laser is off. Resume (insitu engrave --resume "
            f"-o {report_dir}) goes on, measuring the pocket first")
