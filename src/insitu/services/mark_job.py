"""The mark job of a set of placements as a file: planned and checked on the measured cloud
(:mod:`insitu.services.plan`), its texts rendered and its serial issued
(:mod:`insitu.services.serials`), written — or, for a resume, planned again exactly as the
job at its path was. ``insitu mark``, ``insitu mark --recipe``, production and the
application's Mark dock write their jobs here; the Place dock previews with
:func:`preview_plans`."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from insitu.errors import ConfigError, InsituError
from insitu.formats.pens import PenTable
from insitu.formats.pointcloud import PointCloud
from insitu.marking import LaserParams, MarkJob, Placement, read_job
from insitu.patterns.fields import Variables
from insitu.services import serials
from insitu.services.plan import PlanOutcome, joined, plan_placements, rig_finding
from insitu.services.station import Station


@dataclass(frozen=True)
class JobRequest:
    """A mark job to plan and write: ``placements`` (world frame) on ``cloud`` (read from
    ``cloud_path``, which the rig check names), written to ``job_path``; ``laser`` and the
    ``pens`` its placements name; ``force``: write a code that would not decode; variable
    data: ``fields`` (NAME → value), the serial ``counter`` (None: beside the job) created
    with first serial ``serial_start``; ``resume``: plan again the job at ``job_path`` as it
    was (its own serial and time; nothing written); ``marking``: the job is to be marked on
    this station now (a cloud of another rig is then refused, not warned)."""

    job_path: Path
    placements: tuple[Placement, ...]
    cloud: PointCloud
    cloud_path: Path | None = None
    laser: LaserParams | None = None
    pens: PenTable | None = None
    force: bool = False
    fields: Mapping[str, str] = field(default_factory=dict)
    counter: Path | None = None
    serial_start: int | None = None
    resume: bool = False
    marking: bool = False


@dataclass(frozen=True)
class WrittenJob:
    """What :func:`write_mark_job` made: each placement's verdict (``outcomes``), the ``job``
    as written (or, resuming, as planned again) and its variable-data ``record`` (None: no
    text uses fields)."""

    outcomes: list[PlanOutcome]
    job: MarkJob
    record: serials.JobVariables | None


def write_mark_job(station: Station, req: JobRequest,
                   save: Callable[[Path, MarkJob], Any] = serials.save_job) -> WrittenJob:
    """Plan ``req`` on the station's driver and write its job to ``req.job_path`` with the
    serial the counter issues (none is issued when a placement is refused: the first refusal
    is raised, naming its placement when there are several). Resuming, the job is planned
    again with the file's own variable data and must be the job that file holds
    (ConfigError otherwise)."""
    rig = (rig_finding(station, req.cloud_path, req.cloud.rig)
           if req.marking and req.cloud_path is not None else None)

    def plan(placements: list[Placement]) -> list[PlanOutcome]:
        return plan_placements(req.cloud, placements, station.driver, req.laser, req.pens,
                               req.force, rig)

    if req.resume:
        if req.counter is not None or req.serial_start is not None:
            raise ConfigError("resume: a resume marks the job's own serial: give no counter "
                              "and no first serial", field="resume")
        path = Path(req.job_path)
        outcomes = serials.replan(path, req.placements, plan, req.fields)
        job = joined(outcomes, req.laser)
        if not path.exists() or read_job(path).digest() != job.digest():
            raise ConfigError(f"resume: {path} does not hold this job; start it without "
                              "resuming", field="resume")
        return WrittenJob(outcomes, job, serials.job_variables(read_job(path), path))
    done = serials.plan_and_save(req.job_path, req.placements, plan,
                                 lambda outcomes: joined(outcomes, req.laser),
                                 counter=req.counter, fields=req.fields,
                                 start=req.serial_start, save=save)
    return WrittenJob(done.result, done.job, done.record)


def preview_plans(station: Station, cloud: PointCloud, placements: Sequence[Placement],
                  pens: PenTable | None = None, job_path: Path | None = None,
                  cloud_path: Path | None = None) -> list[PlanOutcome]:
    """The verdict of every placement as marking would give it, before anything is written:
    texts rendered with the counter's next serial (beside ``job_path``; 1 without one) and the
    time now — a preview: marking takes the serial. A text that cannot be rendered is refused
    with its one-line message; the cloud's rig is checked as for marking on this station."""
    nxt = (serials.counter_next(serials.default_counter(job_path))
           if job_path is not None else None)
    values = Variables(1 if nxt is None else nxt)
    rendered, errors = [], {}
    for i, p in enumerate(placements):
        try:
            rendered.append(serials.render_placement(p, values))
        except InsituError as e:
            errors[i] = PlanOutcome.refused("text", str(e))
    rig = None if cloud_path is None else rig_finding(station, cloud_path, cloud.rig)
    planned = iter(plan_placements(cloud, rendered, station.driver, pens=pens, rig=rig))
    return [errors[i] if i in errors else next(planned) for i in range(len(placements))]


def laser_of(pen: str | None = None, pens: Path | None = None,
             **given: float) -> tuple[LaserParams, PenTable | None]:
    """The laser settings a job is marked with, and the pen table its paths carry: ``pen`` of
    the table in ``pens`` (a pens file or a project; None: the built-in pens) with the
    settings ``given`` (``power_pct``, ``frequency_khz``, ``mark_speed_mm_s``,
    ``jump_speed_mm_s``; None: the pen's) in its place; without a pen, the settings given
    over the defaults and no table."""
    from insitu.formats.pens import DEFAULT_PENS
    from insitu.formats.project import load_pens

    given = {k: v for k, v in given.items() if v is not None}
    if pen is None and pens is None:
        return LaserParams(**given), None
    table = load_pens(pens) if pens is not None else DEFAULT_PENS
    chosen = table.pen(pen, "pen" if pens is None else str(pens)).model_copy(update=given)
    return (LaserParams(**{k: getattr(chosen, k) for k in LaserParams.model_fields}),
            PenTable(default=chosen.name, pens=(chosen,)))
