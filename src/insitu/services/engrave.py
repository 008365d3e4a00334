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
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from insitu.devices.clock import StepTime, StepTimer
from insitu.errors import ConfigError, FormatError, MeasurementError, SafetyError
from insitu.formats.calibration import HeightCalibration
from insitu.formats.materials import DEFAULT_MATERIALS, MaterialTable
from insitu.formats.pens import PenTable
from insitu.formats.pointcloud import PointCloud
from insitu.marking import (
    Limits,
    Placement,
    check_targets,
    estimate_time,
    make_job,
    progress_path_for,
    read_job,
    read_journal,
    with_pen,
    write_job,
)
from insitu.marking.engrave_depth import (
    UNMEASURED,
    DepthMap,
    DepthSettings,
    Outline,
    PocketCells,
)
from insitu.marking.engrave_layers import layer_paths, passes_given
from insitu.marking.engrave_plan import CellHistory, Learnt, learn, plan_round
from insitu.marking.engrave_record import (
    EngraveAsk,
    EngraveRecord,
    RoundRecord,
    read_record,
    write_record,
)
from insitu.marking.journal import journal_path_for
from insitu.marking.surface import Surface
from insitu.services.common import Progress
from insitu.services.engrave_report import centres as _centres
from insitu.services.engrave_report import depth_picture, histogram_picture
from insitu.services.engrave_report import measure_summary as _summary
from insitu.services.mark import mark
from insitu.services.plan import plan_mark
from insitu.services.pocket import measure_pocket
from insitu.services.scan import Cancelled
from insitu.services.station import Station

NO_HEIGHT_CAL = ("warning: no height calibration: the depth scans' scale is the light plane's "
                 "alone, good to about ±2 % of the depth")
MAX_ROUNDS = 60
MAX_PASSES = 1000
"""The most passes an engraving plans (at the table's rate): a deeper target is beyond reach."""


@dataclass(frozen=True)
class EngraveRequest:
    """An engraving: ``placement`` (world frame) on ``cloud`` (the surface before it) to
    ``depth_mm``, measured every ``rescan_every`` passes at most, ``material`` of
    ``materials``; the record, jobs and pictures in ``report_dir``. ``height_cal``: the
    depth scans' heights (None: the light plane alone); ``spacing_mm``: their lines';
    ``resume``: go on with the engraving in ``report_dir`` (measured first);
    ``open_loop_passes``: instead, this many passes everywhere and nothing measured (what
    counting passes gives); ``materials_from``: where ``materials`` was read (said once)."""

    report_dir: Path
    placement: Placement
    cloud: PointCloud
    depth_mm: float
    rescan_every: int = 10
    material: str = "stainless-steel"
    materials: MaterialTable = DEFAULT_MATERIALS
    height_cal: HeightCalibration | None = None
    spacing_mm: float = 0.1
    settings: DepthSettings = field(default_factory=DepthSettings)
    resume: bool = False
    open_loop_passes: int | None = None
    materials_from: str = "the built-in table"

    def ask(self) -> EngraveAsk:
        p = self.placement
        return EngraveAsk(pattern=p.pattern, at_mm=p.at_mm, width_mm=p.width_mm,
                          rotate_deg=p.rotate_deg, depth_mm=self.depth_mm,
                          rescan_every=self.rescan_every, material=self.material,
                          open_loop_passes=self.open_loop_passes)


@dataclass(frozen=True)
class EngraveOutcome:
    """How it ended (``record.state``: done, held, cancelled), the ``record`` and the last
    depth map (None: never measured)."""

    record: EngraveRecord
    last: DepthMap | None


Notify = Callable[[str], None]
Measured = Callable[[DepthMap, dict], None]     # each measurement: its map, its summary


class _Engraving:
    """One engraving's state between its steps (see the module docstring)."""

    def __init__(self, station: Station, req: EngraveRequest, notify: Notify | None,
                 measured: Measured | None = None):
        self.station, self.req = station, req
        self.notify = notify or (lambda text: None)
        self.measured = measured or (lambda dm, summary: None)
        self.material = req.materials.material(req.material)
        self.nominal = self.material.depth_per_pass_mm(req.materials.laser)
        if self.nominal <= 0:
            raise ConfigError(f"material {req.material!r}: its pen stays below the ablation "
                              "threshold (nothing would be removed)", field="material")
        pen = self.material.pen
        placement = replace(req.placement, hatch_mm=self.material.hatch_mm, pen=pen.name)
        plan = plan_mark(req.cloud, placement, station.driver,
                         pens=PenTable(default=pen.name, pens=(pen,)))
        self.pattern = plan.pattern
        self.limits = Limits.of(station.rig.head)
        self._check_reach(req, np.vstack([p.points for p in plan.job.paths]))
        region = self.pattern.to_shapely()
        if region.is_empty or region.area <= 0:
            raise FormatError(f"pattern {placement.pattern}: no filled area to engrave (only "
                              "lines); a pocket needs a filled shape", field="pattern")
        s = req.settings
        self.region, self.outline = region, Outline(region, s.ring_mm + s.cell_mm)
        self.cells: PocketCells = self.outline.cells(s.cell_mm)
        x0, y0, x1, y1 = region.bounds
        self.top = Surface(req.cloud, region=(x0 - 2, x1 + 2, y0 - 2, y1 + 2))
        self.trusted_to = np.where(self.cells.inside, np.maximum(
            self.cells.edge_mm - s.wall_band_mm, 0.0) / s.bias_per_depth, 0.0)
        self.last: DepthMap | None = None

    def _check_reach(self, req: EngraveRequest, targets: np.ndarray) -> None:
        """Refuse a depth the table's rate would need more than :data:`MAX_PASSES` for, or
        whose floor leaves the focus range (``targets`` (N, 3): the pattern on the top)."""
        passes = req.depth_mm / self.nominal
        if passes > MAX_PASSES:
            raise ConfigError(f"depth {req.depth_mm:g} mm is beyond reach in {req.material}: "
                              f"{passes:.0f} passes at the table's {self.nominal * 1e3:.2f} "
                              f"µm per pass (at most {MAX_PASSES})", field="depth_mm")
        try:
            check_targets(targets - [0.0, 0.0, req.depth_mm], self.limits)
        except SafetyError as e:
            raise SafetyError(f"depth {req.depth_mm:g} mm: the pocket's floor {e}",
                              e.where_mm) from None

    # -- steps ---------------------------------------------------------------------------
    def new_record(self) -> EngraveRecord:
        c = self.cells
        return EngraveRecord(request=self.req.ask(), material=self.material.model_dump(
            mode="json"), nominal_rate_mm=self.nominal,
            cells={"origin": c.origin.tolist(), "cell_mm": c.cell_mm, "shape": list(c.shape)},
            history=CellHistory.start(c.shape, self.nominal).to_dict())

    def save(self, record: EngraveRecord, history: CellHistory) -> None:
        record.history = history.to_dict()
        write_record(self.req.report_dir, record)

    def mark_round(self, record: EngraveRecord, history: CellHistory, passes: np.ndarray,
                   finishing: bool, cancel, progress) -> bool:
        """Plan, write and mark one round; False when it was cancelled (recorded)."""
        k = len(record.rounds) + 1
        paths = layer_paths(self.pattern.contours, self.cells, passes,
                            self.material.hatch_mm, lambda xy: self.top.sample(xy).z,
                            history.estimate, history.rate, record.layers)
        pts = [p for _, p in paths]
        check_targets(np.vstack(pts), self.limits)
        pen = self.material.pen
        job = with_pen(make_job(pts).model_copy(update={"rig": self.req.cloud.rig}), pen)
        name = f"round-{k:02d}.json"
        job_path = self.req.report_dir / name
        write_job(job_path, job)
        rnd = RoundRecord(job=name, layers=int(passes.max()), paths=len(pts),
                          finishing=finishing, passes=passes.astype(int).tolist())
        record.rounds.append(rnd)
        self.save(record, history)
        self.notify(f"round {k}: {rnd.layers} layers, {len(pts)} paths, "
                    f"{estimate_time(job).total_s:.1f} s of marking")
        timer = StepTimer(self.station.clock)
        try:
            result = mark(job, self.station.driver, self.station.devices.controller,
                          progress_path_for(job_path), cancel=cancel, progress=progress)
        except Cancelled:
            self.cut_short(record, history, "cancelled", timer.elapsed())
            return False
        except BaseException:
            self.cut_short(record, history, "interrupted", timer.elapsed())
            raise
        if result.state != "done":
            self.cut_short(record, history, "cancelled", timer.elapsed())
            return False
        history.given(passes)
        record.layers += rnd.layers
        rnd.state, rnd.marking_s = "marked", _seconds(timer.elapsed())
        self.save(record, history)
        return True

    def cut_short(self, record: EngraveRecord, history: CellHistory, state: str,
                  spent: StepTime | None = None) -> None:
        """The last round stopped early: its passes counted from its journal; its marking
        time ``spent`` (None: a resume, which knows the share of the job's estimate done)."""
        rnd = record.rounds[-1]
        job_path = self.req.report_dir / rnd.job
        job = read_job(job_path)
        s = read_journal(journal_path_for(job_path))
        done = np.zeros(len(job.paths), bool)
        if s is not None:
            done[sorted(s.done)] = True
        given = passes_given([p.points for p in job.paths], done, self.cells,
                             np.asarray(rnd.passes, float))
        history.given(given)
        record.layers += rnd.layers
        rnd.state = "cut"
        rnd.marking_s = (_seconds(spent) if spent is not None else
                         estimate_time(job).total_s * float(done.mean()) if len(done) else 0.0)
        record.state = state
        self.save(record, history)
        self.notify(f"round {len(record.rounds)} {state} after {int(done.sum())} of "
                    f"{len(done)} paths")

    def finish(self, record: EngraveRecord, history: CellHistory, held: np.ndarray,
               state: np.ndarray) -> None:
        """The outcome: done, or held (cells hidden by a wall left short); the floor's cells
        the last measurement could not vouch for (beyond the wall band, not measured: their
        depth is the model's) named in a warning; the report's pictures."""
        record.state = "held" if held.any() else "done"
        model = self.cells.inside & (state == UNMEASURED)
        record.outcome = {"held_cells": int(held.sum()), "held_at_mm": _centres(self.cells, held),
                          "model_cells": int(model.sum()),
                          "model_at_mm": _centres(self.cells, model),
                          "station_s": station_seconds(record)}
        if model.any():
            self.notify(f"warning: {int(model.sum())} cells of {self.req.placement.pattern} "
                        "not measured: their depth follows the model, not the measurement")
        self.final_pictures(history)
        self.save(record, history)

    def final_pictures(self, history: CellHistory) -> None:
        """The report's depth map and histogram of the last measurement (the histogram's
        band: ± half a pass, the stop's tolerance)."""
        if self.last is not None:
            depth_picture(self.req.report_dir / "depth-map.png", self.last, self.req.depth_mm,
                          f"{self.req.placement.pattern}: {self.req.material}")
            histogram_picture(self.req.report_dir / "histogram.png", self.last,
                              self.req.depth_mm, 0.5 * float(np.median(history.rate)))

    def measure(self, record: EngraveRecord, history: CellHistory, cancel, progress
                ) -> tuple[DepthMap, Learnt]:
        """Scan the pocket, map its depth, learn the rate; recorded."""
        req = self.req
        timer = StepTimer(self.station.clock)
        try:
            scan = measure_pocket(self.station, self.region, req.settings, req.spacing_mm,
                                  req.height_cal, cancel, progress, self.outline, self.cells,
                                  history.estimate)
        except Cancelled:
            record.state = "cancelled"
            self.save(record, history)
            raise
        dm = scan.map
        learnt = learn(history, dm, self.nominal)
        k = len(record.measures) + 1
        record.measures.append(_summary(len(record.rounds), dm, learnt, history, req.depth_mm,
                                        scan.frames,
                                        _seconds(timer.elapsed())))
        self.last = dm
        depth_picture(req.report_dir / f"measure-{k:02d}.png", dm, req.depth_mm,
                      f"measure {k}, after round {len(record.rounds)}")
        self.save(record, history)
        m = record.measures[-1]
        mean = (f"mean depth {m['mean_mm']:.4f} mm ± {m['sem_mm']:.4f}"
                if m["mean_mm"] is not None else "no floor point beyond the walls' bias zone")
        self.notify(f"measured after round {len(record.rounds)}: {mean}, rate "
                    f"{learnt.rate_mm * 1e3:.2f} µm/pass, {m['at_depth']} cells at depth, "
                    f"{m['short']} short, {m['cells']['unmeasured']} not measured")
        self.measured(dm, m)
        return dm, learnt


def engrave(station: Station, req: EngraveRequest, cancel: threading.Event | None = None,
            progress: Progress | None = None, notify: Notify | None = None,
            measured: Measured | None = None) -> EngraveOutcome:
    """Engrave ``req`` on ``station`` (see the module docstring). The laser is off when this
    returns or raises; the record says how far it got. Refused (SafetyError, nothing marked)
    like any mark; ConfigError for a report folder holding another engraving, or a finished
    or interrupted one without ``resume``."""
    e = _Engraving(station, req, notify, measured)
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
        if e.mark_round(record, history, passes, True, cancel, progress):
            record.state = "done"
            e.save(record, history)
        return EngraveOutcome(record, None)
    while len(record.rounds) < MAX_ROUNDS:
        plan = plan_round(history, state, req.depth_mm, req.rescan_every, e.trusted_to, sigma)
        if plan.layers == 0:
            e.finish(record, history, plan.held, state)
            return EngraveOutcome(record, e.last)
        if not e.mark_round(record, history, plan.passes, plan.finishing, cancel, progress):
            return EngraveOutcome(record, e.last)
        dm, learnt = e.measure(record, history, cancel, progress)
        if learnt.cells and learnt.rate_mm < 0.05 * e.nominal:
            raise MeasurementError(f"the passes so far removed {learnt.rate_mm * 1e3:.2f} µm "
                                   f"per pass, {learnt.rate_mm / e.nominal:.0%} of the "
                                   f"{req.material} table's: check the laser, the focus and "
                                   "the material")
        state, sigma = dm.state, dm.sem
    raise MeasurementError(f"the pocket is not at depth after {MAX_ROUNDS} rounds")


def _resumed(e: _Engraving, record: EngraveRecord, req: EngraveRequest) -> CellHistory:
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


def _seconds(t: StepTime) -> float:
    """A step's station seconds (a real rig's: the wall clock's)."""
    return float(t.station if t.station is not None else t.wall)


def station_seconds(record: EngraveRecord) -> dict[str, float]:
    """The station's seconds: marking (each round's estimate, the part marked of a round cut
    short) and scanning, by the station's clock, and their total."""
    marking = sum(r.marking_s for r in record.rounds)
    scanning = sum(m["scan_s"] for m in record.measures)
    return {"marking": round(marking, 1), "scanning": round(scanning, 1),
            "total": round(marking + scanning, 1)}
