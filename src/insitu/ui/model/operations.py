"""What each action of the application does, in terms of the services the headless commands
use (no Qt, no algorithm of its own). Every function here may run on a worker thread: it
takes a ``progress(done, total)`` callback and a ``cancel`` Event where the work is long."""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from insitu import services
from insitu.errors import InsituError, SafetyError
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.marking import GalvoDriver, LaserParams, MarkJob, RunResult
from insitu.services import mark as mark_svc
from insitu.services.common import Progress
from insitu.services.station import Station
from insitu.services.station import connect as connect_station
from insitu.ui.project_file import SUFFIX, Project, read_project, write_project
from insitu.ui.session import PlanOutcome, RigChoice, ScanSettings

_WHERE = re.compile(r"\(x, y\) = \((-?[\d.]+), (-?[\d.]+)\) mm")


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
        raise InsituError("connect the rig first (Rig ▸ Connect)")
    return services.scan_live(station.world, settings.spacing_mm, settings.region, height_cal,
                              progress=progress, cancel=cancel, on_frame=on_frame,
                              exposure_ms=settings.exposure_ms, speed_mm_s=settings.speed_mm_s,
                              camera=station.devices.camera, head=station.devices.head)


def where(error: SafetyError) -> tuple[float, float] | None:
    """The (x, y) mm a SafetyError names, if it names one."""
    m = _WHERE.search(str(error))
    return (float(m.group(1)), float(m.group(2))) if m else None


def plan_all(cloud: PointCloud, placements, driver: GalvoDriver,
             laser: LaserParams | None = None) -> list[PlanOutcome]:
    """:func:`services.mark.plan_mark` of each placement; a refusal is kept as its message."""
    out = []
    for p in placements:
        try:
            out.append(PlanOutcome(plan=mark_svc.plan_mark(cloud, p, driver, laser)))
        except SafetyError as e:
            out.append(PlanOutcome(error=str(e), where=where(e)))
        except InsituError as e:
            out.append(PlanOutcome(error=str(e)))
    return out


class AbortableController:
    """A controller that stops at once: once ``abort`` is set it sends no further command,
    turns the laser off and raises :class:`~insitu.services.Cancelled` (the cut path is not
    counted as marked, so a resumed job marks it again). Otherwise it forwards to ``inner``."""

    def __init__(self, inner, abort: threading.Event):
        self.inner, self.abort = inner, abort

    def execute(self, commands) -> None:
        for c in commands:
            if self.abort.is_set():
                self.inner.laser_off()
                raise services.Cancelled("marking aborted by the operator")
            self.inner.execute([c])

    def laser_off(self) -> None:
        self.inner.laser_off()


@dataclass(frozen=True)
class MarkOutcome:
    """``result`` of the run, and the camera ``image`` (H, W) uint8 of the marked part."""

    result: RunResult
    image: np.ndarray


def preview(job: MarkJob, station: Station) -> list[np.ndarray]:
    """Draw the job's outline with the pilot laser; returns the outline's (2, 3) mm segments."""
    from insitu.marking import preview_outlines, run_preview

    run_preview(job, station.driver, station.devices.controller)
    return [seg for loop in preview_outlines(job) for seg in np.stack([loop[:-1], loop[1:]], 1)]


def mark(job: MarkJob, station: Station, job_path: Path | None, progress: Progress,
         cancel: threading.Event) -> MarkOutcome:
    """Mark ``job`` (progress recorded beside ``job_path`` when given), then image the part.
    Setting ``cancel`` stops the laser before the next command (Cancelled is raised)."""
    controller = AbortableController(station.devices.controller, cancel)
    ppath = mark_svc.save_job(job_path, job) if job_path is not None else None
    result = mark_svc.mark(job, station.driver, controller, ppath, cancel=cancel,
                           progress=progress)
    return MarkOutcome(result, station.devices.camera.grab())


@dataclass(frozen=True)
class OpenedProject:
    project: Project
    cloud: PointCloud | None
    height_cal: object


def open_project(path: Path, progress: Progress | None = None) -> OpenedProject:
    """Read a project and what it names (cloud, height calibration)."""
    project = read_project(path)
    cloud = read_ply(project.cloud) if project.cloud is not None else None
    cal = (services.load_height_calibration(project.height_cal, progress)
           if project.height_cal is not None else None)
    return OpenedProject(project, cloud, cal)


def save_project(path: Path, project: Project, cloud: PointCloud | None,
                 job: MarkJob | None) -> Project:
    """Write the cloud (when it is not on disk yet) and the job beside ``path``, then the
    project file; returns the project as written (with those paths)."""
    stem = path.name[:-len(SUFFIX)] if path.name.endswith(SUFFIX) else path.stem
    if cloud is not None and project.cloud is None:
        project = replace(project, cloud=path.with_name(stem + ".cloud.ply"))
        write_ply(project.cloud, cloud)
    if job is not None:
        project = replace(project, job=path.with_name(stem + ".job.json"))
        mark_svc.save_job(project.job, job)
    else:
        project = replace(project, job=None)
    write_project(path, project)
    return project


# -- calibration pages ---------------------------------------------------------------------
@dataclass(frozen=True)
class CalibrationOutcome:
    """What a calibration page shows: ``residuals`` (name → value), ``notes`` and a
    ``picture`` (H, W) or (H, W, 3) uint8 (BGR), and the file it wrote."""

    residuals: dict[str, float]
    notes: str
    picture: np.ndarray
    path: Path


def _middle_frame(folder: Path) -> np.ndarray:
    from insitu.formats.sequence import Sequence

    seq = Sequence.open(folder)
    image = cv2.imread(str(seq.folder / seq.frames[len(seq) // 2].file), cv2.IMREAD_UNCHANGED)
    if image.dtype != np.uint8:
        image = (image >> 8).astype(np.uint8)
    return image


def calibrate(kind: str, folder: Path, out: Path, progress: Progress) -> CalibrationOutcome:
    """``kind`` "camera", "height" or "field": fit from the recorded ``folder``, write ``out``
    (JSON; the field's report PNG beside it) as the headless commands do."""
    from insitu.rig.files import save_json_model

    if kind == "field":
        from insitu.services.field import calibrate_and_report
        cal = calibrate_and_report(folder, out, progress=progress)
        picture = cv2.imread(str(out.with_suffix(".png")), cv2.IMREAD_COLOR)
    elif kind == "camera":
        from insitu.calibrate.report import bars_image
        from insitu.services.camera import calibrate_camera_recording
        cal = calibrate_camera_recording(folder, progress=progress)
        save_json_model(out, cal)
        picture = (bars_image(cal.per_view_rms_px, f"reprojection RMS per view, px (all: "
                              f"{cal.rms_px:.3f} px)") if cal.per_view_rms_px
                   else _middle_frame(folder))
    elif kind == "height":
        from insitu.services.height import calibrate_height_and_report
        cal = calibrate_height_and_report(folder, out, progress)
        picture = cv2.imread(str(out.with_suffix(".png")), cv2.IMREAD_COLOR)
    else:
        raise ValueError(kind)
    return CalibrationOutcome(dict(cal.residuals), cal.notes or "", picture, out)
