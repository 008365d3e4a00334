"""The steps of one engraving (:class:`EngraveSteps`): its pocket and cells checked and laid
out, a round planned and marked, the pocket measured and the rate learnt, a round cut short
counted from its journal, the outcome and its pictures; and the station seconds they took.
:mod:`insitu.services.engrave` runs them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from insitu.devices.clock import StepTime, StepTimer
from insitu.errors import ConfigError, FormatError, SafetyError
from insitu.formats.pens import PenTable
from insitu.marking import (
    LaserOverride,
    Limits,
    check_targets,
    estimate_time,
    make_job,
    progress_path_for,
    read_job,
    read_journal,
    write_job,
)
from insitu.marking.engrave_depth import UNMEASURED, DepthMap, Outline, PocketCells
from insitu.marking.engrave_layers import layer_paths, passes_given
from insitu.marking.engrave_plan import CellHistory, Learnt, RoundPlan, finishing_pen, learn
from insitu.marking.engrave_record import EngraveRecord, RoundRecord, write_record
from insitu.marking.engrave_walls import trusted_depth
from insitu.marking.journal import journal_path_for
from insitu.marking.surface import Surface
from insitu.services.engrave_report import centres as _centres
from insitu.services.engrave_report import depth_picture, histogram_picture
from insitu.services.engrave_report import measure_summary as _summary
from insitu.services.engrave_request import EngraveRequest, Measured, Notify
from insitu.services.mark import mark
from insitu.services.plan import plan_mark
from insitu.services.pocket import LINES_ALONG, measure_pocket
from insitu.services.scan import Cancelled
from insitu.services.station import Station

MAX_PASSES = 1000
"""The most passes an engraving plans (at the table's rate): a deeper target is beyond reach."""


class EngraveSteps:
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
        self.finish_pen, self.speed = finishing_pen(self.material, req.materials.laser)
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
        self.trusted_to = np.where(self.cells.inside, trusted_depth(
            self.outline.wall_distances(*self.cells.centres(), LINES_ALONG), s), 0.0)
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

    def round_job(self, record: EngraveRecord, history: CellHistory, plan: RoundPlan):
        """The round's mark job: the pen's layers, then the finishing pen's, the focus on the
        floor each begins at."""
        top = self.top.sample
        first = layer_paths(self.pattern.contours, self.cells, plan.passes,
                            self.material.hatch_mm, lambda xy: top(xy).z, history.estimate,
                            history.rate, record.layers)
        fine = layer_paths(self.pattern.contours, self.cells, plan.finish,
                           self.material.hatch_mm, lambda xy: top(xy).z,
                           history.estimate + plan.passes * history.rate,
                           history.rate / self.speed, record.layers + int(plan.passes.max()))
        pts = [p for _, p in first] + [p for _, p in fine]
        check_targets(np.vstack(pts), self.limits)
        pen, fpen = LaserOverride.of_pen(self.material.pen), LaserOverride.of_pen(self.finish_pen)
        job = make_job(pts, overrides={i: pen if i < len(first) else fpen
                                       for i in range(len(pts))})
        return job.model_copy(update={"rig": self.req.cloud.rig})

    def mark_round(self, record: EngraveRecord, history: CellHistory, plan: RoundPlan,
                   cancel, progress) -> bool:
        """Plan, write and mark one round; False when it was cancelled (recorded)."""
        k = len(record.rounds) + 1
        job = self.round_job(record, history, plan)
        name = f"round-{k:02d}.json"
        job_path = self.req.report_dir / name
        write_job(job_path, job)
        rnd = RoundRecord(job=name, layers=plan.layers, paths=len(job.paths),
                          finishing=plan.finishing, passes=plan.passes.tolist())
        if plan.finishing:
            rnd.finish, rnd.finish_speed = plan.finish.tolist(), self.speed
            rnd.finish_pen = self.finish_pen.model_dump(mode="json")
        record.rounds.append(rnd)
        self.save(record, history)
        fine = (f" ({int(plan.finish.max())} finishing: {self.finish_pen.name}, "
                f"{self.finish_pen.summary()})" if plan.finishing else "")
        self.notify(f"round {k}: {rnd.layers} layers{fine}, {len(job.paths)} paths, "
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
        history.given(plan.equivalent(self.speed))
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
        fine = np.array([p.laser is not None and p.laser.pen == rnd.finish_pen["name"]
                         if rnd.finish_pen else False for p in job.paths], bool)
        pts = [p.points for p in job.paths]
        given = passes_given([p for p, f in zip(pts, fine) if not f], done[~fine], self.cells,
                             np.asarray(rnd.passes, float))
        if rnd.finish is not None:
            given += passes_given([p for p, f in zip(pts, fine) if f], done[fine], self.cells,
                                  np.asarray(rnd.finish, float)) / rnd.finish_speed
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
