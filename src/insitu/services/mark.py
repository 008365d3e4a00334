"""Marking use cases: place a pattern on a measured cloud, make the checked job, preview it
with the pilot laser, mark it (the board stopped at once when cancelled) and image the
result."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from insitu.devices.galvo import check_lists
from insitu.errors import FormatError, InsituError, SafetyError
from insitu.formats.atomic import atomic_write_bytes
from insitu.formats.pens import DEFAULT_PENS, PenTable
from insitu.formats.pointcloud import PointCloud, read_ply
from insitu.marking import (GalvoDriver, JournalSummary, LaserParams, MarkJob, Placement,
                            Projection, RunResult, TimeEstimate, estimate_time, history,
                            plan_job, progress_path_for, run_job, run_preview, with_pen,
                            write_job)
from insitu.marking.verify import CodeCheck, check_code, unrolled
from insitu.patterns import Pattern
from insitu.services.common import Progress
from insitu.services.scan import Cancelled
from insitu.services.room_light import station_room_light

if TYPE_CHECKING:
    from insitu.services.station import Station


@dataclass(frozen=True)
class MarkPlan:
    """A checked job and how it came about: ``pattern`` placed (world x, y before
    projection), ``projection`` (support, stretch), ``estimate`` of the marking time,
    ``codes``: whether each code reads from the job's marks."""

    job: MarkJob
    pattern: Pattern
    projection: Projection
    estimate: TimeEstimate
    codes: tuple[CodeCheck, ...] = ()


def check_codes(job: MarkJob, pattern: Pattern, projection: Projection,
                beam_mm: float) -> tuple[CodeCheck, ...]:
    """Decode the code of ``pattern`` (if any) from the job's marks: their x, y, or unrolled
    along the surface when the projection has an unroll direction (wrap)."""
    if pattern.code is None or pattern.frame is None:
        return ()
    paths3d = [p.points for p in job.paths]
    if projection.direction_deg is not None and projection.anchor is not None:
        paths_xy = unrolled(paths3d, projection.anchor, projection.direction_deg)
    else:
        paths_xy = [p[:, :2] for p in paths3d]
    return (check_code(pattern, paths_xy, beam_mm)[0],)


def plan_mark(cloud: PointCloud | str | Path, placement: Placement, driver: GalvoDriver,
              laser: LaserParams | None = None, force: bool = False,
              pens: PenTable | None = None) -> MarkPlan:
    """Place, project and check: SafetyError (naming the place) for a pattern outside the
    field or focus range, over a hole or a wall, or whose corrected commands leave the field;
    FormatError for a bad pattern, a pen not in ``pens``, or a code that would not decode from
    the planned marks (unless ``force``). With ``pens`` (or a placement naming a pen: then of
    :data:`DEFAULT_PENS`) every path carries its pen's settings. Nothing is written or
    fired."""
    pen = None
    if pens is not None or placement.pen is not None:
        pen = (pens or DEFAULT_PENS).pen(placement.pen, f"placement {placement.pattern}")
    pattern = placement.placed()
    polylines = placement.polylines(pattern)
    if not isinstance(cloud, PointCloud):
        cloud = read_ply(cloud)
    job, proj = plan_job(polylines, cloud, driver.limits, placement.mode, laser,
                         anchor=placement.at_mm)
    job = job.model_copy(update={"rig": cloud.rig})     # the job records the cloud's rig
    if pen is not None:
        job = with_pen(job, pen)
    driver.check(job)
    codes = check_codes(job, pattern, proj, placement.beam_mm)
    bad = [c for c in codes if not c.ok]
    if bad and not force:
        c = bad[0]
        wall = (f", {proj.unmarked_fraction:.1%} of its path left unmarked at a step's wall: "
                "place it off the step" if proj.unmarked_mm > 0 else "")
        raise FormatError(f"{c.name}: does not decode from the planned marks (read "
                          f"{c.decoded!r}, module {c.module_mm:.3g} mm{wall}); nothing written "
                          "(--force to mark it anyway)")
    return MarkPlan(job, pattern, proj, estimate_time(job, driver.timing), codes)


@dataclass(frozen=True)
class PlanOutcome:
    """The plan of one placement: ``plan`` when it passed the checks, else the one-line
    ``error`` and, when the refusal knows one, the place ``where`` (x, y) mm."""

    plan: MarkPlan | None = None
    error: str | None = None
    where: tuple[float, float] | None = None


def plan_all(cloud: PointCloud, placements, driver: GalvoDriver,
             laser: LaserParams | None = None, pens: PenTable | None = None
             ) -> list[PlanOutcome]:
    """:func:`plan_mark` of each placement; a refusal is kept as its message (and place).
    A code whose quiet zone another placement's marks enter is refused, and so is the
    placement whose marks enter it (each naming the other, the place where they meet)."""
    out = []
    for p in placements:
        try:
            out.append(PlanOutcome(plan=plan_mark(cloud, p, driver, laser, pens=pens)))
        except SafetyError as e:
            out.append(PlanOutcome(error=str(e), where=e.where_mm))
        except InsituError as e:
            out.append(PlanOutcome(error=str(e)))
    return _quiet_zones_clear(out)


def joined(outcomes: list[PlanOutcome]) -> MarkJob | None:
    """One job marking every planned placement in order (None: none, or one refused)."""
    if not outcomes or any(o.plan is None for o in outcomes):
        return None
    first = outcomes[0].plan.job
    return first.model_copy(update={"paths": [path for o in outcomes
                                              for path in o.plan.job.paths]})


def _quiet_zones_clear(outcomes: list[PlanOutcome]) -> list[PlanOutcome]:
    """``outcomes`` with a refusal for each code whose frame — symbol and quiet zone —
    another planned pattern's marks (world x, y, as placed) reach into, and for that
    pattern."""
    import shapely

    out = list(outcomes)
    marks = [None if o.plan is None else shapely.union_all(
        [o.plan.pattern.to_shapely(), *map(shapely.LineString, o.plan.pattern.paths)])
        for o in outcomes]
    for i, o in enumerate(outcomes):
        code = None if o.plan is None else o.plan.pattern
        if code is None or code.code is None or code.frame is None:
            continue
        zone = shapely.Polygon(code.frame)
        for j, m in enumerate(marks):
            if j == i or m is None or not m.intersects(zone):
                continue
            c = m.intersection(zone).representative_point()
            out[i] = PlanOutcome(error=f"{code.name}: placement {j + 1}'s marks enter its "
                                       "quiet zone (a reader needs it clear)", where=(c.x, c.y))
            if out[j].plan is not None:
                out[j] = PlanOutcome(error=f"{outcomes[j].plan.pattern.name}: its marks enter "
                                           f"the quiet zone of placement {i + 1} "
                                           f"({code.name})", where=(c.x, c.y))
            break
    return out


def unfinished(job: MarkJob, job_path: str | Path) -> JournalSummary | None:
    """The record of an earlier run of ``job`` at ``job_path`` that did not finish (None:
    none, finished, or another job's)."""
    s = history(job, progress_path_for(job_path))
    return None if s is None or s.state == "done" or s.finished else s


def save_job(path: str | Path, job: MarkJob) -> Path:
    """Write ``job`` atomically and drop a progress record of an older job at the same place
    (a new job starts from its first path). Returns the progress file's path."""
    ppath = progress_path_for(path)
    write_job(path, job)
    ppath.unlink(missing_ok=True)
    return ppath


class _Abortable:
    """Sends each path to ``inner`` whole (a board enables its laser per list). Once ``cancel``
    is set, a watcher stops the board at once — ``inner.laser_off()``, which every controller
    takes from another thread: it stops the list — and the path ends in Cancelled (recorded
    as not completed, so a resume marks it again)."""

    def __init__(self, inner, cancel: threading.Event):
        self.inner, self.cancel = inner, cancel

    def execute(self, commands) -> None:
        done = threading.Event()

        def watch() -> None:
            while not done.is_set():
                if self.cancel.wait(0.005):
                    self.inner.laser_off()
                    return

        if not self.cancel.is_set():
            watcher = threading.Thread(target=watch, name="abort watcher", daemon=True)
            watcher.start()
            try:
                self.inner.execute(commands)
            finally:
                done.set()
                watcher.join()
        if self.cancel.is_set():
            self.inner.laser_off()
            raise Cancelled("marking aborted by the operator")

    def laser_off(self) -> None:
        self.inner.laser_off()

    def check(self, lists) -> None:
        check_lists(self.inner, lists)

    def position(self):
        get = getattr(self.inner, "position", None)
        return get() if get is not None else None


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
    not recorded), the camera's ``image`` (H, W) of the marked part (None: not asked) and
    the marks read back from it (``insitu.services.inspect.ReadBack``; None: not read)."""

    result: RunResult
    progress_path: Path | None
    image: np.ndarray | None = None
    readback: object | None = None


def mark_on_station(station: Station, job: MarkJob, job_path: str | Path | None = None, *,
                    resume: bool = False, restart: bool = False, cut_path: str | None = None,
                    preview: bool = False,
                    inspect: str | Path | None = None, image: bool = False,
                    cancel: threading.Event | None = None,
                    progress: Progress | None = None) -> StationRun:
    """:func:`mark` ``job`` with the station's driver and controller, its journal and progress
    recorded beside ``job_path`` (the job file; None: not recorded); then image the marked part
    under the room light, auto-exposed, when ``image`` is set or ``inspect`` names the .png
    to write."""
    ppath = progress_path_for(job_path) if job_path is not None else None
    result = mark(job, station.driver, station.devices.controller, ppath, resume, preview,
                  cancel, progress, restart, cut_path)
    picture = station_room_light(station).image if image or inspect is not None else None
    if inspect is not None:
        save_image(inspect, picture)
    return StationRun(result, ppath, picture)


def save_image(path: str | Path, image: np.ndarray) -> None:
    """Write a camera image as PNG, atomically."""
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise FormatError(f"{path}: OpenCV could not encode the image")
    atomic_write_bytes(path, buf.tobytes())
