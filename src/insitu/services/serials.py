"""Variable data of mark jobs: the placements' texts rendered (``{serial}``, ``{date}``, the
user's fields), the serial taken from the counter when the job is planned, and the record the
job file keeps of it — its optional ``variable_data`` field (the mark job of
docs/formats.md lets a job carry fields of its own):

    "variable_data": {"serial": 42, "counter": "serial.counter.json",
                      "time": "2026-12-02T01:02:03+01:00", "fields": {"gtin": "0950…"},
                      "texts": [{"spec": "qr:\\"{serial}\\"", "text": "42"}]}

A serial is issued when its job is written: the counter moves on (fsynced) before the job file
is, so a job that is refused while planning takes none, and one that faults, is aborted or is
never marked keeps its serial — planning again takes the next. A resume renders with the
job's own record, so it marks the same serial.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Any, Generic, TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError

from insitu.errors import FormatError
from insitu.formats.counter import locked, read_counter
from insitu.formats.validation import validation_message
from insitu.marking import MarkJob, Placement, progress_path_for, write_job
from insitu.patterns.fields import Variables, is_template, render_spec, template_fields, uses_serial
from insitu.patterns.load import spec_parts

COUNTER_NAME = "serial.counter.json"
T = TypeVar("T")


def save_job(path: str | Path, job: MarkJob) -> Path:
    """Write ``job`` atomically and drop a progress record of an older job at the same place
    (a new job starts from its first path). Returns the progress file's path."""
    ppath = progress_path_for(path)
    write_job(path, job)
    ppath.unlink(missing_ok=True)
    return ppath


class _Text(BaseModel):
    model_config = ConfigDict(extra="allow", frozen=True)
    spec: str
    text: str


class JobVariables(BaseModel):
    """A job's ``variable_data``: its ``serial`` (None: its texts use none), the ``counter``
    it came from (relative to the job's folder), the local ``time`` of planning (ISO 8601),
    the user's ``fields`` and each templated placement's spec and rendered ``texts``."""

    model_config = ConfigDict(extra="allow", frozen=True)
    serial: int | None = None
    counter: str | None = None
    time: str
    fields: dict[str, str] = {}
    texts: list[_Text] = []

    def variables(self) -> Variables:
        """The values the job's texts were rendered with."""
        return Variables(self.serial, dict(self.fields), datetime.fromisoformat(self.time))

    def counter_path(self, job_path: str | Path) -> Path | None:
        """The counter's path (None: the job names none)."""
        return None if self.counter is None else Path(job_path).parent / self.counter


def default_counter(job_path: str | Path) -> Path:
    """Where a job's counter is kept unless told: ``serial.counter.json`` in the job's folder
    (a project's job is beside the project, so the project's counter is that one too)."""
    return Path(job_path).parent / COUNTER_NAME


def is_templated(placements: Sequence[Placement]) -> bool:
    """Any placement's text holds fields (or braces, even malformed: rendering says why)."""
    return any(is_template(p.pattern) for p in placements)


def render_placement(p: Placement, values: Variables) -> Placement:
    """``p`` with its text rendered by ``values`` (FormatError naming a field without a
    value or with a format spec that does not fit)."""
    return replace(p, pattern=render_spec(p.pattern, values))


def job_variables(job: MarkJob, job_path: str | Path = "job") -> JobVariables | None:
    """The job's ``variable_data`` record (None: it has none); FormatError naming the field."""
    data = (job.model_extra or {}).get("variable_data")
    if data is None:
        return None
    try:
        rec = JobVariables.model_validate(data)
        rec.variables()
        return rec
    except ValidationError as e:
        raise FormatError(validation_message(job_path, e, "variable_data")) from None
    except ValueError:
        raise FormatError(f"{job_path}: variable_data.time: expected an ISO 8601 time, got "
                          f"{data.get('time')!r}") from None


def _record(placements, rendered, values: Variables, counter: Path | None,
            job_path: Path) -> dict[str, Any]:
    texts = [{"spec": p.pattern, "text": spec_parts(r.pattern)[1]}
             for p, r in zip(placements, rendered) if template_fields(p.pattern)]
    rel = None if counter is None else os.path.relpath(counter.absolute(),
                                                       job_path.absolute().parent)
    used = {n for p in placements for n in template_fields(p.pattern)}
    return JobVariables(serial=values.serial, counter=rel,
                        time=values.time.isoformat(timespec="seconds"),
                        fields={k: v for k, v in values.fields.items() if k in used},
                        texts=texts).model_dump(mode="json", exclude_none=True)


@dataclass(frozen=True)
class Planned(Generic[T]):
    """What :func:`plan_and_save` made: the planner's ``result``, the ``job`` as written
    (with its ``variable_data``) and its ``record`` (None: no placement is templated)."""

    result: T
    job: MarkJob
    record: JobVariables | None


def plan_and_save(job_path: str | Path, placements: Sequence[Placement],
                  plan: Callable[[list[Placement]], T], job_of: Callable[[T], MarkJob], *,
                  counter: str | Path | None = None, fields: Mapping[str, str] | None = None,
                  start: int | None = None, now: datetime | None = None,
                  save: Callable[[Path, MarkJob], Any] = save_job) -> Planned[T]:
    """Render the placements' texts, ``plan`` them and ``save`` the job to ``job_path``.
    When a text uses ``{serial}`` the counter (``counter``, default beside the job; created
    with first serial ``start`` when given) is held locked from reading its next serial to
    issuing it, which happens after planning succeeded and before the job is written.
    FormatError when the counter is missing (and no ``start``), exists although ``start`` is
    given, or a field has no value."""
    job_path = Path(job_path)
    values = Variables(None, dict(fields or {}), now or datetime.now().astimezone())
    if not any(uses_serial(p.pattern) for p in placements):
        if start is not None:
            raise FormatError("serial start: no pattern uses {serial}", field="serial_start")
        return _plan(job_path, placements, plan, job_of, values, None, save)
    counter = Path(counter) if counter is not None else default_counter(job_path)
    with locked(counter) as c:
        if start is not None:
            c.create(start)
        values = replace(values, serial=c.next)
        return _plan(job_path, placements, plan, job_of, values, counter, save,
                     issue=lambda job: c.issue(values.serial, job_path.name, job.digest()))


def _plan(job_path: Path, placements, plan, job_of, values: Variables, counter: Path | None,
          save, issue: Callable[[MarkJob], None] | None = None) -> Planned:
    rendered = [render_placement(p, values) for p in placements]
    result = plan(rendered)
    job, rec = job_of(result), None
    if is_templated(placements):
        data = _record(placements, rendered, values, counter, job_path)
        job, rec = job.model_copy(update={"variable_data": data}), JobVariables(**data)
    if issue is not None:
        issue(job)
    save(job_path, job)
    return Planned(result, job, rec)


def replan(job_path: str | Path, placements: Sequence[Placement],
           plan: Callable[[list[Placement]], T], fields: Mapping[str, str] | None = None) -> T:
    """``plan`` the placements again as the job at ``job_path`` was planned (for a resume):
    rendered with its recorded serial, time and fields; with ``fields`` and the time now when
    it has no record (a job without variable data). Takes no serial."""
    from insitu.marking import read_job

    job_path = Path(job_path)
    rec = job_variables(read_job(job_path), job_path) if job_path.exists() else None
    values = rec.variables() if rec is not None else Variables(None, dict(fields or {}))
    return plan([render_placement(p, values) for p in placements])


def counter_next(path: Path | None) -> int | None:
    """The counter's next serial (None: no path, or no counter there)."""
    return read_counter(path).next if path is not None and path.exists() else None
