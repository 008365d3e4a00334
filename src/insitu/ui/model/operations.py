"""What the application's actions do beyond the services (no Qt, no algorithm of its own):
connect with the camera answering, the scan source, the pilot preview's trace, marking with
the job beside the project, the calibration pages. Every function here may run on a worker
thread: it takes a ``progress(done, total)`` callback and a ``cancel`` Event where the work
is long."""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from insitu import services
from insitu.errors import InsituError
from insitu.formats.project import RigChoice, ScanSettings
from insitu.marking import MarkJob
from insitu.services import mark as mark_svc
from insitu.services.common import Progress
from insitu.services.serials import save_job
from insitu.services.station import Station
from insitu.services.station import connect as connect_station

NO_RIG = "connect the rig first (Rig ▸ Connect)"


def connect(choice: RigChoice, field: Path | None = None) -> Station:
    """The station of ``choice`` (its rig file, or the simulated rig), its camera answering."""
    station = connect_station(choice.rig_file, choice.workpiece, choice.seed, choice.binning,
                              field)
    try:
        station.devices.camera.grab()   # the camera answers (the simulator builds its scene)
    except BaseException:
        station.close()
        raise
    return station


def scan(station: Station | None, settings: ScanSettings, height_cal, progress: Progress,
         cancel: threading.Event, on_frame) -> services.ScanResult:
    """Replay ``settings.replay`` or drive the rig over ``settings.region``; Method 2 with a
    height calibration, else Method 1."""
    if settings.replay is not None:
        return services.scan_replay(settings.replay, height_cal, progress=progress,
                                    cancel=cancel, on_frame=on_frame)
    if station is None:
        raise InsituError(NO_RIG)
    return services.scan_live(station, settings.spacing_mm, settings.region, height_cal,
                              progress=progress, cancel=cancel, on_frame=on_frame,
                              exposure_ms=settings.exposure_ms, speed_mm_s=settings.speed_mm_s)


def preview(job: MarkJob, station: Station) -> list[np.ndarray]:
    """Draw the job's outline with the pilot laser; returns the outline's (2, 3) mm segments."""
    from insitu.marking import preview_outlines, run_preview

    run_preview(job, station.driver, station.devices.controller)
    return [seg for loop in preview_outlines(job) for seg in np.stack([loop[:-1], loop[1:]], 1)]


def mark(job: MarkJob, station: Station, job_path: Path | None, progress: Progress,
         cancel: threading.Event, resume: bool = False, restart: bool = False,
         cut_path: str | None = None, outcomes=None, cloud=None, write: bool = True
         ) -> mark_svc.StationRun:
    """Write ``job`` to ``job_path`` (when given and ``write``, unless resuming; its journal
    is kept beside it; ``write`` False: the job is that file, as ``insitu job run``), mark it
    (``resume`` / ``restart`` / ``cut_path`` as :func:`~insitu.marking.run_job`), image the
    part and read the marks of ``outcomes`` (the plans of ``job``'s placements, on ``cloud``)
    back. Setting ``cancel`` stops the laser before the next command. A job planned for
    another rig or workpiece is refused
    (SafetyError), nothing written or fired."""
    station.check_source(job_path or Path("the job"), job.rig, "job")
    if job_path is not None and write and not resume:
        save_job(job_path, job)
    run = mark_svc.mark_on_station(station, job, job_path, resume=resume, restart=restart,
                                   cut_path=cut_path, image=True, cancel=cancel,
                                   progress=progress)
    return read_back(run, station, outcomes, cloud)


def read_back(run: mark_svc.StationRun, station: Station, outcomes, cloud
              ) -> mark_svc.StationRun:
    """``run`` with the marks of ``outcomes`` read back from its image when it finished
    (:func:`insitu.services.inspect.read_back`); unchanged when there is nothing to read."""
    from insitu.services.inspect import read_back as read

    if (run.image is None or run.result.state != "done" or cloud is None or not outcomes
            or any(o.plan is None for o in outcomes)):
        return run
    result = read(station, [o.plan for o in outcomes], cloud, image=run.image)
    return dataclasses.replace(run, readback=result)


def preview_serial(job_path: Path | None) -> int:
    """The serial a preview of variable data shows: the counter's next (1 without one)."""
    from insitu.services.serials import counter_next, default_counter

    nxt = counter_next(default_counter(job_path)) if job_path is not None else None
    return 1 if nxt is None else nxt


def mark_serial(items, cloud, laser, station: Station, job_path: Path | None,
                progress: Progress, cancel: threading.Event, pens=None) -> mark_svc.StationRun:
    """Plan ``items`` (with variable data) again with the serial taken from the counter
    beside the job — issued once every placement passed its checks, before the job is
    written (:func:`insitu.services.mark_job.write_mark_job`) — then mark it as :func:`mark`
    does."""
    from insitu.services.mark_job import JobRequest, write_mark_job
    from insitu.services.serials import default_counter

    if job_path is None:
        raise InsituError("save the project first: the serial counter is kept beside it")
    counter = default_counter(job_path)
    if not counter.exists():
        raise InsituError(f"no serial counter beside the project: in its folder, insitu serial "
                          f"set {counter.name} FIRST_SERIAL creates it")
    done = write_mark_job(station, JobRequest(job_path, tuple(items), cloud, laser=laser,
                                              pens=pens, counter=counter, marking=True))
    run = mark_svc.mark_on_station(station, done.job, job_path, image=True, cancel=cancel,
                                   progress=progress)
    return read_back(run, station, done.outcomes, cloud)


def unfinished(job: MarkJob, job_path: Path | None):
    """The journal summary of an unfinished earlier run of ``job`` at ``job_path`` (None:
    none)."""
    return None if job_path is None else mark_svc.unfinished(job, job_path)


@dataclass(frozen=True)
class CalibrationOutcome:
    """What a calibration page shows: ``residuals`` (name → value), ``notes`` and a
    ``picture`` (H, W) or (H, W, 3) uint8 (BGR), and the file it wrote."""

    residuals: dict[str, float]
    notes: str
    picture: np.ndarray
    path: Path


def calibrate(kind: str, folder: Path, out: Path, progress: Progress) -> CalibrationOutcome:
    """``kind`` "camera", "height" or "field": fit from the recorded ``folder`` and write
    ``out`` (JSON) with its picture beside it (.png), as the headless commands do."""
    if kind == "camera":
        from insitu.services.camera import calibrate_camera_and_report
        cal = calibrate_camera_and_report(folder, out, progress=progress)
    elif kind == "height":
        from insitu.services.height import calibrate_height_and_report
        cal = calibrate_height_and_report(folder, out, progress)
    elif kind == "field":
        from insitu.services.field import calibrate_and_report
        cal = calibrate_and_report(folder, out, progress=progress)
    else:
        raise ValueError(kind)
    picture = cv2.imread(str(out.with_suffix(".png")), cv2.IMREAD_COLOR)
    return CalibrationOutcome(dict(cal.residuals), cal.notes or "", picture, out)


RECORDED = {"height": "height-calibration", "field": "field-calibration"}
"""The calibrations recorded on the connected rig (the camera's needs the board moved)."""


def record_calibration(station: Station, kind: str, folder: Path, progress: Progress,
                       cancel: threading.Event) -> Path:
    """Record the ``kind`` calibration ("height" or "field") on ``station`` into the new
    ``folder``; setting ``cancel`` stops it between frames (Cancelled, the head off, the
    folder removed). On the simulated rig the parts go back on the table after."""
    import shutil

    from insitu.errors import ConfigError
    from insitu.services.record import record

    if kind not in RECORDED:
        raise ConfigError(f"{kind} calibration: recorded with insitu sim record "
                          "camera-calibration (the board is moved between views)")
    folder = Path(folder)
    if folder.exists() and any(folder.iterdir()):
        raise ConfigError(f"{folder}: not empty: choose a new folder for the recording")

    def step(done: int, total: int) -> None:
        if cancel.is_set():
            raise services.Cancelled(f"{kind} calibration: recording cancelled")
        progress(done, total)

    world = station.world
    parts = list(world.parts) if world is not None else None
    try:
        return record(station, RECORDED[kind], folder, progress=step)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    finally:
        if world is not None:
            world.parts = parts
            world.invalidate()
