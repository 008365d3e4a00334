"""Production: part after part, wait for the start, scan the region, locate the part, plan the
recipe's placements where the part lies, mark them as one job, read the mark back and log one
record (:mod:`insitu.formats.production_log`).

Serials: the job of a part is written by :func:`insitu.services.mark_job.write_mark_job`, so a part
refused while locating or planning takes no serial, and a part whose marking faults or is aborted
keeps the one it was issued (logged with it). ``resume`` finishes that part with its own job — its
journal decides what is marked again (the paths not done, the cut path again whole) — and carries on
with the next part number. A device fault or an abort ends the run (the laser off, the record
written, the error raised); a refusal sets the part aside and the run goes on. A part whose
read-back fails (a mark not the plan, or farther from its planned place than the recipe's
``read.offset_tolerance_mm``) is logged "marked" with the reason as its error
(:func:`~insitu.services.part_reading.reading_fault`). A scan along y whose lines leave the part's
pose unheld (its edges along them) gets a second look: the part scanned again, crossed, where it
lies (:func:`_locate`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Protocol

from insitu.devices.clock import StepTimer
from insitu.errors import DeviceError, FormatError, InsituError
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.formats.production_log import PartRecord, append_record, read_log
from insitu.formats.recipe import Recipe
from insitu.geometry.pose import pose_matrix
from insitu.locate.part import LocateRefused
from insitu.marking import LaserParams, MarkJob, history, progress_path_for, read_job
from insitu.services import mark as mark_svc
from insitu.services import serials
from insitu.services.height import crossed_model
from insitu.services.locate import Located, Locator
from insitu.services.mark_job import JobRequest, WrittenJob, write_mark_job
from insitu.services.part_reading import ReadBackFn, reading_fault
from insitu.services.scan import Cancelled, ScanResult, scan_live
from insitu.services.station import Station
from insitu.services.survey import scan_found


class StartSignal(Protocol):
    """What starts a part: the operator's Enter, a stage or IO input of a real station.
    ``wait`` returns when part ``part`` may start; it raises Cancelled once ``cancel`` is set
    (or the operator declines)."""

    def wait(self, part: int, cancel: threading.Event) -> None: ...


class NoWait:
    """Start every part at once (the simulated rig, tests: no hand on the keyboard)."""

    def wait(self, part: int, cancel: threading.Event) -> None:
        if cancel.is_set():
            raise Cancelled(f"production stopped before part {part}")


@dataclass
class Production:
    """A run: the ``recipe``, the ``station``, the ``log`` (JSON lines; the CSV beside it and
    each part's job ``part-NNNN.job.json`` in its folder), parts numbered 1 … ``count``.
    ``locate``: the part's pose from a scan; ``read_back``: what the camera reads of the mark
    (None: the read-back is not made); ``present``: puts part k on the table and returns its
    true pose (the simulated rig; None: the operator does); ``start``: the start signal;
    ``height_cal``: the scans' height calibration (None: Method 1); ``on_record``: sees each
    record as it is logged; ``on_stage``: (part, stage name) as each stage begins."""

    recipe: Recipe
    station: Station
    log: Path
    count: int
    locate: Locator
    read_back: ReadBackFn | None = None
    present: Callable[[int], Any] | None = None
    start: StartSignal = field(default_factory=NoWait)
    cancel: threading.Event = field(default_factory=threading.Event)
    height_cal: Any = None
    on_record: Callable[[PartRecord], None] | None = None
    on_stage: Callable[[int, str], None] | None = None

    def job_path(self, part: int) -> Path:
        return self.log.parent / f"part-{part:04d}.job.json"

    def cloud_path(self, part: int) -> Path:
        return self.log.parent / f"part-{part:04d}.cloud.ply"


@dataclass
class _Part:
    """What is known of a part as it goes through the stages."""

    number: int
    times: dict[str, float] = field(default_factory=dict)
    station: dict[str, float | None] = field(default_factory=dict)
    cpu: dict[str, float] = field(default_factory=dict)
    fields: dict[str, Any] = field(default_factory=dict)
    serial: int | None = None
    job: Path | None = None

    def record(self, outcome: str, error: str | None = None, **more) -> PartRecord:
        return PartRecord(part=self.number, serial=self.serial, outcome=outcome,
                          job=None if self.job is None else self.job.name, error=error,
                          time=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                          **{f"{k}_s": round(v, 3) for k, v in self.times.items()},
                          **{f"{k}_station_s": None if v is None else round(v, 3)
                             for k, v in self.station.items()},
                          **{f"{k}_cpu_s": round(v, 3) for k, v in self.cpu.items()},
                          **self.fields, **more)


def scan_region(run: Production) -> tuple[float, float, float, float]:
    """The recipe's region, or where the part lies (the station knows it on the simulated
    rig) grown by the margin."""
    s = run.recipe.scan
    if s.region is not None:
        return s.region
    x0, x1, y0, y1 = run.station.default_region()
    m = s.margin_mm
    return x0 - m, x1 + m, y0 - m, y1 + m


def resume_point(records: list[PartRecord]) -> tuple[int, PartRecord | None]:
    """(the next part number, the interrupted part's last record or None) from a log."""
    if not records:
        return 1, None
    last = records[-1]
    if last.outcome in ("fault", "aborted"):
        return last.part, last
    return last.part + 1, None


def produce(run: Production, resume: bool = False) -> list[PartRecord]:
    """Run parts until ``run.count`` are through (``resume``: continue the log). Returns this
    call's records. FormatError for a log that exists without ``resume`` or is not this run's;
    a fault or an abort is raised after its record is logged (the laser off).
    MeasurementError before the first part when the recipe scans crossed and the height
    calibration has no crossed lines."""
    if run.recipe.scan.cross and run.height_cal is not None:
        crossed_model(run.height_cal)        # one line before the first part when it has none
    records = read_log(run.log)
    if records and not resume:
        raise FormatError(f"{run.log}: holds {len(records)} records of an earlier run: "
                          "resume it, or give another log")
    first, pending = resume_point(records)
    out = []
    for number in range(first, run.count + 1):
        part = _Part(number)
        try:
            run.start.wait(number, run.cancel)
            if run.present is not None:
                run.present(number)
            if pending is not None and pending.part == number and pending.serial is not None:
                rec = _finish(run, part, pending)
            else:
                rec = _run_part(run, part)
        except (InsituError, KeyboardInterrupt) as e:
            rec = part.record(_outcome(e), _text(e), resumed=pending is not None
                              and pending.part == number)
            _log(run, rec, out)
            raise
        _log(run, rec, out)
    return out


def _log(run: Production, rec: PartRecord, out: list) -> None:
    append_record(run.log, rec)
    out.append(rec)
    if run.on_record is not None:
        run.on_record(rec)


def _outcome(e: BaseException) -> str:
    """"aborted" by the operator (a cancel, Ctrl-C), else "fault"."""
    return "aborted" if isinstance(e, (Cancelled, KeyboardInterrupt)) else "fault"


def _text(e: BaseException) -> str:
    return str(e) or type(e).__name__


def _stage(run: Production, part: _Part, name: str, work: Callable[[], Any]) -> Any:
    """``work()`` as stage ``name`` of ``part``, its seconds (wall, station, CPU:
    :class:`~insitu.devices.clock.StepTimer`) added to the stage's."""
    if run.on_stage is not None:
        run.on_stage(part.number, name)
    timer = StepTimer(run.station.clock)
    try:
        with timer:
            return work()
    finally:
        t = timer.result
        part.times[name] = part.times.get(name, 0.0) + t.wall
        part.cpu[name] = part.cpu.get(name, 0.0) + t.cpu
        before = part.station.get(name, 0.0)
        part.station[name] = (None if t.station is None or before is None
                              else before + t.station)


def _run_part(run: Production, part: _Part) -> PartRecord:
    scanned = _scan_part(run, part, "scan", scan_region(run), run.recipe.scan.cross, True)
    try:
        cloud, located = _locate(run, part, scanned)
        x, y, a = located.pose()
        part.fields.update(x_mm=x, y_mm=y, angle_deg=a, fitness=round(located.fitness, 4),
                           rmse_mm=round(located.rmse_mm, 4), image_edges=located.image_edges)
        planned = _stage(run, part, "plan", lambda: plan_part(run, part, cloud, located))
    except (Cancelled, DeviceError):
        raise
    except InsituError as e:                 # no serial was issued: the part is set aside
        if part.serial is not None:
            raise
        return part.record("refused", _text(e))
    _stage(run, part, "mark", lambda: _mark(run, planned.job, part.job))
    return _read(run, part, planned.outcomes, cloud)


def _scan_part(run: Production, part: _Part, stage: str, region, cross: bool,
               survey: bool = False) -> ScanResult:
    """The part's scan over ``region`` as the recipe says (``cross``: with the crossed pass;
    with ``survey`` and the recipe's ``survey_mm`` its lines only over the part and its
    margin as a first pass found them: :func:`~insitu.services.survey.scan_found`), its
    cloud written where the run keeps the part's cloud."""
    s = run.recipe.scan

    def scan() -> ScanResult:
        settings = dict(spacing=s.spacing_mm, exposure_ms=s.exposure_ms,
                        speed_mm_s=s.speed_mm_s, cancel=run.cancel, cross=cross,
                        cross_spacing=s.cross_spacing_mm, lines_per_frame=s.lines_per_frame)
        if survey and s.survey_mm is not None:
            return scan_found(run.station, region, s.survey_mm, s.margin_mm, run.height_cal,
                              **settings)
        return scan_live(run.station, region=region, height_cal=run.height_cal, **settings)

    scanned = _stage(run, part, stage, scan)
    write_ply(run.cloud_path(part.number), scanned.cloud)
    return scanned


def _locate(run: Production, part: _Part, scanned: ScanResult) -> tuple[PointCloud, Located]:
    """(the cloud the part was located on, its pose, from the cloud and the scan's
    room-light frame). The second look: when lines along y alone leave the pose unheld
    (edges along them: LocateRefused with the refused pose) and the recipe allows it, the
    part is scanned again, crossed, over its footprint at that pose grown by the margin, and
    located on that scan (its time in ``rescan_s``)."""
    try:
        return scanned.cloud, _stage(run, part, "locate",
                                     lambda: run.locate(scanned.cloud, scanned.room_light))
    except LocateRefused as e:
        if e.best is None or not _second_look(run):
            raise
        region = _footprint(run, e.best)
    again = _scan_part(run, part, "rescan", region, True)
    return again.cloud, _stage(run, part, "locate",
                               lambda: run.locate(again.cloud, again.room_light))


def _second_look(run: Production) -> bool:
    s, cal = run.recipe.scan, run.height_cal
    return s.second_look and not s.cross and (cal is None or cal.sheet_cross is not None)


def _footprint(run: Production, best) -> tuple[float, float, float, float]:
    """The part's reference laid at the refused pose ``best`` (a locate Solution), its
    x, y extent grown by the margin, within the scan region."""
    reference = getattr(run.locate, "reference", None)
    x0, x1, y0, y1 = scan_region(run)
    if reference is None:
        return x0, x1, y0, y1
    T = pose_matrix(best.x_mm, best.y_mm, best.angle_deg)
    xy = reference.points[:, :2] @ T[:2, :2].T + T[:2, 3]
    lo = xy.min(axis=0) - run.recipe.scan.margin_mm
    hi = xy.max(axis=0) + run.recipe.scan.margin_mm
    return (max(x0, float(lo[0])), min(x1, float(hi[0])),
            max(y0, float(lo[1])), min(y1, float(hi[1])))


def _mark(run: Production, job: MarkJob, path: Path, **resume) -> None:
    """Mark the part's job; Cancelled when the run was stopped between its paths."""
    done = mark_svc.mark_on_station(run.station, job, path, cancel=run.cancel, **resume)
    if done.result.state != "done":
        raise Cancelled(f"marking {done.result.state} after {done.result.completed} of "
                        f"{done.result.total} paths; the laser is off")


def plan_part(run: Production, part: _Part, cloud: PointCloud,
              located: Located) -> WrittenJob:
    """The recipe's job for this part (its serial and job file noted as soon as written)."""
    def save(p: Path, job: MarkJob):
        part.job = p
        part.serial = ((job.model_extra or {}).get("variable_data") or {}).get("serial")
        return serials.save_job(p, job)

    return plan_recipe(run.station, run.recipe, cloud, located, run.job_path(part.number),
                       save=save)


def recipe_request(recipe: Recipe, cloud: PointCloud, located: Located, job_path: Path,
                   cloud_path: Path | None = None, resume: bool = False,
                   marking: bool = False) -> JobRequest:
    """The job request of ``recipe`` for a part located at ``located`` on ``cloud``: every
    placement moved where the part lies, the recipe's laser and fields, its counter (default
    beside the job, created with its first serial when missing)."""
    counter = (recipe.counter if recipe.counter is not None
               else Path(job_path).parent / serials.COUNTER_NAME)
    start = (recipe.serial_start if recipe.serial_start is not None and not counter.exists()
             else None)
    return JobRequest(Path(job_path), tuple(p.in_world(located.T_world_part)
                                            for p in recipe.placements),
                      cloud, cloud_path, LaserParams(**recipe.laser), fields=recipe.fields,
                      counter=None if resume else counter,
                      serial_start=None if resume else start, resume=resume, marking=marking)


def plan_recipe(station: Station, recipe: Recipe, cloud: PointCloud, located: Located,
                job_path: Path, cloud_path: Path | None = None, marking: bool = False,
                save: Callable[[Path, MarkJob], Any] = serials.save_job) -> WrittenJob:
    """Every placement of ``recipe`` moved where the part lies, planned on its ``cloud`` and
    written to ``job_path`` as one job with the serial the recipe's counter issues
    (:func:`insitu.services.mark_job.write_mark_job`); InsituError naming the first placement
    refused."""
    return write_mark_job(station, recipe_request(recipe, cloud, located, job_path, cloud_path,
                                                  marking=marking), save)


def _read(run: Production, part: _Part, outcomes, cloud: PointCloud,
          resumed: bool = False) -> PartRecord:
    if run.read_back is None:
        return part.record("marked", resumed=resumed)
    plans = [o.plan for o in outcomes]
    got = _stage(run, part, "read", lambda: run.read_back(
        run.station, plans, cloud, run.log.parent / f"part-{part.number:04d}.readback.png"))
    return part.record("marked", reading_fault(got, run.recipe.read_tolerance_mm),
                       decoded=got.decoded, decode_ok=got.ok, grade=got.grade,
                       offset_mm=None if got.offset_mm is None else round(got.offset_mm, 4),
                       resumed=resumed)


def _finish(run: Production, part: _Part, last: PartRecord) -> PartRecord:
    """The interrupted part, still on the table, with its own job and serial: the paths its
    journal does not record as done (a cut path marked again whole), then the read-back of
    the job planned again as it was (its recorded serial, on its cloud and pose)."""
    if last.job is None or last.x_mm is None:
        raise FormatError(f"{run.log}: part {last.part} holds serial {last.serial} but names no "
                          "job and pose to finish")
    path = run.log.parent / last.job
    job = read_job(path)
    part.serial, part.job = last.serial, path
    part.fields.update({k: getattr(last, k) for k in ("x_mm", "y_mm", "angle_deg", "fitness",
                                                      "rmse_mm")})
    left = mark_svc.unfinished(job, path)
    done = left is None and history(job, progress_path_for(path)) is not None
    if not done:
        _stage(run, part, "mark", lambda: _mark(
            run, job, path, resume=left is not None,
            cut_path="remark" if left is not None and left.cut is not None else None))
    cloud = read_ply(run.cloud_path(part.number))
    located = Located(pose_matrix(last.x_mm, last.y_mm, last.angle_deg), last.fitness or 0.0,
                      last.rmse_mm or 0.0)
    again = write_mark_job(run.station, recipe_request(run.recipe, cloud, located, path,
                                                       resume=True))
    return _read(run, part, again.outcomes, cloud, resumed=True)

