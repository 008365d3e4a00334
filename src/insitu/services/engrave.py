"""Engraving to a depth, measuring between passes: the use case of ``insitu engrave`` (a typed
request in, a typed outcome out, like :mod:`insitu.services.mark_job`).

The placement is planned and checked on the measured cloud as any mark (field, focus, holes,
walls); its filled region is the pocket. Then rounds: the passes each cell of the pocket still
needs (:mod:`insitu.marking.engrave_plan`) as layers of hatch (:mod:`insitu.marking.
engrave_layers`) with the focus on the floor, written as a mark job beside the record and
marked with its journal (:func:`insitu.services.mark.mark`: ABORT stops the board at once);
then a local scan of the pocket (lines across it and the top around it, their centres found
without smoothing along the line) measures the depth per cell
(:mod:`insitu.marking.engrave_depth`), and the rate is learnt. It stops when every cell it can
see is at depth (within half a pass), or when the cells left short are ones the camera cannot
see (``held``: they had passes only while the model said they were short, never more). The
record (``engrave.json``) is rewritten after every step: a resume counts the passes of a round
cut short from its journal and measures the pocket before anything else.

Station time: the station's own clock (:mod:`insitu.devices.clock`) over each round's marking
and each depth scan; a real rig's, which has none, the wall clock's.
"""

from __future__ import annotations

import threading

import numpy as np

from insitu.errors import ConfigError, FormatError, MeasurementError, SafetyError
from insitu.marking.engrave_plan import CellHistory, RoundPlan, plan_round
from insitu.marking.engrave_record import EngraveRecord, read_record
from insitu.services.common import Progress
from insitu.services.engrave_request import (
    NO_HEIGHT_CAL,
    EngraveOutcome,
    EngraveRequest,
    Measured,
    Notify,
)
from insitu.services.engrave_steps import EngraveSteps, station_seconds
from insitu.services.station import Station

MAX_ROUNDS = 60

__all__ = ["NO_HEIGHT_CAL", "EngraveOutcome", "EngraveRequest", "engrave", "station_seconds"]


def engrave(station: Station, req: EngraveRequest, cancel: threading.Event | None = None,
            progress: Progress | None = None, notify: Notify | None = None,
            measured: Measured | None = None) -> EngraveOutcome:
    """Engrave ``req`` on ``station`` (see the module docstring). The laser is off when this
    returns or raises; the record says how far it got. Refused (SafetyError, nothing marked)
    like any mark; ConfigError for a report folder holding another engraving, or a finished
    or interrupted one without ``resume``."""
    e = EngraveSteps(station, req, notify, measured)
    e.notify(f"materials: {req.materials_from}")
    if req.height_cal is None and req.open_loop_passes is None:
        e.notify(NO_HEIGHT_CAL)
    req.report_dir.mkdir(exist_ok=True)
    record = read_record(req.report_dir)
    if record is None:
        if req.resume:
            raise ConfigError(f"resume: {req.report_dir} holds no engraving to resume",
                              field="resume")
        record = e.new_record()
        history = CellHistory.from_dict(record.history)
        e.save(record, history)
        state, sigma = np.where(e.cells.inside, 0, -1), None
    else:
        history = _resumed(e, record, req)
        dm, _ = e.measure(record, history, cancel, progress)
        state, sigma = dm.state, dm.sem
    if req.open_loop_passes is not None:
        passes = np.where(e.cells.inside, req.open_loop_passes, 0)
        plan = RoundPlan(passes, np.zeros_like(passes), np.zeros(passes.shape, bool))
        if e.mark_round(record, history, plan, cancel, progress):
            record.state = "done"
            e.save(record, history)
        return EngraveOutcome(record, None)
    while len(record.rounds) < MAX_ROUNDS:
        plan = plan_round(history, state, req.depth_mm, req.rescan_every, e.trusted_to, sigma,
                          e.speed)
        if plan.layers == 0:
            e.finish(record, history, plan.held, state)
            return EngraveOutcome(record, e.last)
        if not e.mark_round(record, history, plan, cancel, progress):
            return EngraveOutcome(record, e.last)
        dm, learnt = e.measure(record, history, cancel, progress)
        if learnt.cells and learnt.rate_mm < 0.05 * e.nominal:
            raise MeasurementError(f"the passes so far removed {learnt.rate_mm * 1e3:.2f} µm "
                                   f"per pass, {learnt.rate_mm / e.nominal:.0%} of the "
                                   f"{req.material} table's: check the laser, the focus and "
                                   "the material")
        state, sigma = dm.state, dm.sem
    raise MeasurementError(f"the pocket is not at depth after {MAX_ROUNDS} rounds")


def _resumed(e: EngraveSteps, record: EngraveRecord, req: EngraveRequest) -> CellHistory:
    """The history of the engraving to go on with; ConfigError when there is none to."""
    where = req.report_dir
    asked = record.request
    if asked != req.ask():
        raise ConfigError(f"{where} holds an engraving of another request ({asked.pattern} at "
                          f"{list(asked.at_mm)}, {asked.depth_mm} mm): give its options, or "
                          "another report folder", field="resume")
    if record.state in ("done", "held"):
        raise ConfigError(f"{where}: the engraving is finished ({record.state}); write a new "
                          "one elsewhere", field="resume")
    if not req.resume:
        raise SafetyError(f"{where}: the engraving was {record.state} after round "
                          f"{len(record.rounds)}: resume it (it measures the pocket first)")
    if record.cells.get("shape") != list(e.cells.shape):
        raise FormatError(f"{where}: cells: the record's grid is not this pocket's")
    history = CellHistory.from_dict(record.history)
    if record.rounds and record.rounds[-1].state == "planned":
        e.cut_short(record, history, "running")
    record.state = "running"
    e.save(record, history)
    return history
