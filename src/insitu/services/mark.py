"""Marking use cases: place a pattern on a measured cloud, make the checked job, preview it
with the pilot laser, mark it and image the result."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_bytes
from insitu.formats.pointcloud import PointCloud, read_ply
from insitu.marking import (GalvoDriver, LaserParams, MarkJob, Projection, RunResult,
                            TimeEstimate, estimate_time, plan_job, progress_path_for,
                            projection_mode, run_job, run_preview, write_job)
from insitu.patterns import Pattern, hatch, load_pattern, order_paths
from insitu.services.common import Progress


@dataclass(frozen=True)
class Placement:
    """Where and how a pattern is marked. ``pattern``: a file or a ``text:``/``qr:`` spec;
    ``at_mm``: its centre, world x, y; ``width_mm``: its width before rotating;
    ``rotate_deg``: CCW about +z; ``mode``: a key of ``marking.PROJECTIONS``; ``hatch_mm``:
    fill spacing (None: outlines only); ``hatch_angle_deg``, ``cross``: the hatch's
    direction(s)."""

    pattern: str
    at_mm: tuple[float, float]
    width_mm: float
    rotate_deg: float = 0.0
    mode: str = "planar"
    hatch_mm: float | None = None
    hatch_angle_deg: float = 0.0
    cross: bool = False

    def placed(self) -> Pattern:
        """The pattern loaded and moved to its place, world mm (FormatError if it cannot be)."""
        projection_mode(self.mode)
        return load_pattern(self.pattern).placed(self.at_mm, self.width_mm, self.rotate_deg)

    def polylines(self, pattern: Pattern) -> list[np.ndarray]:
        """What to mark of the placed ``pattern``, in marking order: hatched fill and outlines
        with ``hatch_mm``, else the outlines and open paths. (N, 2) world mm each."""
        if self.hatch_mm is not None:
            return hatch(pattern, self.hatch_mm, self.hatch_angle_deg, self.cross,
                         start=self.at_mm)
        if pattern.is_empty:
            raise FormatError(f"pattern {pattern.name}: empty (nothing to mark)")
        loops = [np.vstack([c, c[:1]]) for c in pattern.contours]
        return order_paths(loops + list(pattern.paths), start=self.at_mm)


@dataclass(frozen=True)
class MarkPlan:
    """A checked job and how it came about: ``pattern`` placed (world x, y before
    projection), ``projection`` (support, stretch), ``estimate`` of the marking time."""

    job: MarkJob
    pattern: Pattern
    projection: Projection
    estimate: TimeEstimate


def plan_mark(cloud: PointCloud | str | Path, placement: Placement, driver: GalvoDriver,
              laser: LaserParams | None = None) -> MarkPlan:
    """Place, project and check: SafetyError (naming the place) for a pattern outside the
    field or focus range, over a hole or a wall, or whose corrected commands leave the field;
    FormatError for a bad pattern. Nothing is written or fired."""
    pattern = placement.placed()
    polylines = placement.polylines(pattern)
    if not isinstance(cloud, PointCloud):
        cloud = read_ply(cloud)
    job, proj = plan_job(polylines, cloud, driver.limits, placement.mode, laser,
                         anchor=placement.at_mm)
    driver.check(job)
    return MarkPlan(job, pattern, proj, estimate_time(job, driver.timing))


def save_job(path: str | Path, job: MarkJob) -> Path:
    """Write ``job`` atomically and drop a progress record of an older job at the same place
    (a new job starts from its first path). Returns the progress file's path."""
    ppath = progress_path_for(path)
    write_job(path, job)
    ppath.unlink(missing_ok=True)
    return ppath


def mark(job: MarkJob, driver: GalvoDriver, controller, progress_path: str | Path | None,
         resume: bool = False, preview: bool = False, cancel: threading.Event | None = None,
         progress: Progress | None = None) -> RunResult:
    """Optionally draw the job's outline with the pilot laser, then mark it (resuming after
    the last completed path with ``resume``). The laser is off when this returns or raises;
    the progress file records how far the job got."""
    if preview:
        run_preview(job, driver, controller)
    return run_job(job, driver, controller, progress_path, resume, cancel, progress)


def save_image(path: str | Path, image: np.ndarray) -> None:
    """Write a camera image as PNG, atomically."""
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise FormatError(f"{path}: OpenCV could not encode the image")
    atomic_write_bytes(path, buf.tobytes())
