"""Marking a written job on the station: previewed with the pilot laser, marked (the board
stopped at once when cancelled) and the result imaged; how long a job takes on the station's
board (:func:`board_seconds`: the plan at the board's own pace, measured on its runs).
Planning is :mod:`insitu.services.plan`, the job file with its serial
:mod:`insitu.services.mark_job`."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from insitu.devices.clock import StepTime, StepTimer
from insitu.devices.galvo import ListPosition, list_digest
from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_bytes
from insitu.marking import (
    GalvoDriver,
    JournalSummary,
    MarkJob,
    RunResult,
    estimate_time,
    history,
    path_seconds,
    progress_path_for,
    run_job,
    run_preview,
)
from insitu.services.common import Progress
from insitu.services.room_light import station_room_light
from insitu.services.scan import Cancelled

if TYPE_CHECKING:
    from insitu.services.station import Station


def unfinished(job: MarkJob, job_path: str | Path) -> JournalSummary | None:
    """The record of an earlier run of ``job`` at ``job_path`` that did not finish (None:
    none, finished, or another job's)."""
    s = history(job, progress_path_for(job_path))
    return None if s is None or s.state == "done" or s.finished else s


class _Abortable:
    """Sends each path to ``inner`` whole (a board enables its laser per list). Once ``cancel``
    is set, a watcher stops the board at once — ``inner.laser_off()``, which every controller
    takes from another thread: it stops the list — and the path ends in Cancelled (recorded
    as not completed, so a resume marks it again). A list not sent because ``cancel`` was
    set already is reported at position 0 (nothing of it marked: a resume continues it from
    its start)."""

    def __init__(self, inner, cancel: threading.Event):
        self.inner, self.cancel = inner, cancel
        self._unsent: str | None = None

    def execute(self, commands) -> None:
        done = threading.Event()

        def watch() -> None:
            while not done.is_set():
                if self.cancel.wait(0.005):
                    self.inner.laser_off()
                    return

        self._unsent = None
        if not self.cancel.is_set():
            watcher = threading.Thread(target=watch, name="abort watcher", daemon=True)
            watcher.start()
            try:
                self.inner.execute(commands)
            finally:
                done.set()
                watcher.join()
        else:
            self._unsent = list_digest(commands)
        if self.cancel.is_set():
            self.inner.laser_off()
            raise Cancelled("marking aborted by the operator")

    def laser_off(self) -> None:
        self.inner.laser_off()

    def check(self, lists) -> None:
        self.inner.check(lists)

    def position(self):
        if self._unsent is not None:
            return ListPosition(self._unsent, 0)
        return self.inner.position()


def mark(job: MarkJob, driver: GalvoDriver, controller, progress_path: str | Path | None,
         resume: bool = False, preview: bool = False, cancel: threading.Event | None = None,
         progress: Progress | None = None, restart: bool = False,
         cut_path: str | None = None) -> RunResult:
    """Optionally draw the job's outline with the pilot laser, then mark it (``resume``: the
    paths not done, the cut path as ``cut_path`` says; ``restart``: again from the start; see
    :func:`~insitu.marking.run_job`). The laser is off when this returns or raises; the
    journal records what the laser did. Once ``cancel`` is set the board stops at once:
    between paths the run ends "cancelled"; within one, the laser goes off and Cancelled is
    raised (that path is recorded as cut, with the board's position when it reports one)."""
    if cancel is not None:
        controller = _Abortable(controller, cancel)
    if preview:
        run_preview(job, driver, controller)
    return run_job(job, driver, controller, progress_path, resume, cancel, progress,
                   restart=restart, cut_path=cut_path)


@dataclass(frozen=True)
class StationRun:
    """A job marked on the station: ``result``, the ``progress_path`` recording it (None:
    not recorded), the camera's ``image`` (H, W) of the marked part (None: not asked), the
    marks read back from it (``insitu.services.inspect.ReadBack``; None: not read) and the
    seconds it took (``time``: station, CPU, wall; :class:`~insitu.devices.clock.StepTime`)."""

    result: RunResult
    progress_path: Path | None
    image: np.ndarray | None = None
    readback: object | None = None
    time: StepTime | None = None


PACE_MEMORY = 0.5
"""Weight of the last run's pace against the earlier ones'."""
PACE_MIN_S = 0.2
"""A run planned shorter than this says too little about the board's pace."""


@dataclass(frozen=True)
class BoardTime:
    """A job's time on a station's board: ``plan_s`` the plan's seconds (jumps, marks,
    passes and delays at the job's speeds, :func:`insitu.marking.estimate_time`), ``pace``
    the board's own pace on its earlier runs (wall seconds per planned second; None: not
    measured yet), the marked and jump lengths ``mark_mm`` and ``jump_mm``."""

    plan_s: float
    mark_mm: float
    jump_mm: float
    pace: float | None = None

    @property
    def total_s(self) -> float:
        return self.plan_s * (self.pace or 1.0)

    def words(self) -> str:
        """"about 12 s", with the board's pace when it is not the plan's."""
        if self.pace is None or abs(self.pace - 1.0) < 0.1:
            return f"about {_seconds(self.total_s)}"
        return (f"about {_seconds(self.total_s)} on this board (its pace: {self.pace:.1f} × "
                f"the plan's {_seconds(self.plan_s)})")


def _seconds(s: float) -> str:
    return f"{s:.1f} s" if s < 10 else f"{s:.0f} s" if s < 120 else f"{s / 60:.1f} min"


def board_seconds(job: MarkJob, station: Station | None, first_path: int = 0) -> BoardTime:
    """How long ``job`` from ``first_path`` on takes on ``station``'s board (None: the plan
    with default delays)."""
    e = estimate_time(job, station.driver.timing if station is not None else None,
                      first_path=first_path)
    return BoardTime(e.total_s, e.mark_mm, e.jump_mm,
                     None if station is None else station.mark_pace)


def _learn_pace(station: Station, job: MarkJob, result: RunResult, done_before: int,
                wall_s: float) -> None:
    """The station's pace from a run that marked ``result.completed − done_before`` paths
    from ``result.start_path`` in ``wall_s`` seconds."""
    n = result.completed - done_before
    if n <= 0:
        return
    planned = float(path_seconds(job, station.driver.timing)[
        result.start_path:result.start_path + n].sum())
    if planned < PACE_MIN_S:
        return
    pace = wall_s / planned
    old = station.mark_pace
    station.mark_pace = pace if old is None else PACE_MEMORY * pace + (1 - PACE_MEMORY) * old


def mark_on_station(station: Station, job: MarkJob, job_path: str | Path | None = None, *,
                    resume: bool = False, restart: bool = False, cut_path: str | None = None,
                    preview: bool = False,
                    inspect: str | Path | None = None, image: bool = False,
                    cancel: threading.Event | None = None,
                    progress: Progress | None = None) -> StationRun:
    """:func:`mark` ``job`` with the station's driver and controller, its journal and progress
    recorded beside ``job_path`` (the job file; None: not recorded); then image the marked part
    under the room light, auto-exposed, when ``image`` is set or ``inspect`` names the .png
    to write. The run's wall time against the plan's is the board's pace from then on
    (``station.mark_pace``)."""
    ppath = progress_path_for(job_path) if job_path is not None else None
    before = history(job, ppath) if resume and ppath is not None else None
    timer = StepTimer(station.clock)
    result = mark(job, station.driver, station.devices.controller, ppath, resume, preview,
                  cancel, progress, restart, cut_path)
    spent = timer.elapsed()
    if not preview:
        _learn_pace(station, job, result, 0 if before is None else len(before.done
                                                                      | before.skipped),
                    spent.wall)
    picture = station_room_light(station).image if image or inspect is not None else None
    if inspect is not None:
        save_image(inspect, picture)
    return StationRun(result, ppath, picture, time=timer.elapsed())


def save_image(path: str | Path, image: np.ndarray) -> None:
    """Write a camera image as PNG, atomically."""
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise FormatError(f"{path}: OpenCV could not encode the image")
    atomic_write_bytes(path, buf.tobytes())
