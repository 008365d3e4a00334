"""Project use cases (``insitu gui``): open a project file with what it names, save the
session's cloud, job and project file side by side."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from insitu.formats.calibration import HeightCalibration
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.formats.project import Project, beside, read_project, write_project
from insitu.marking import PROJECTIONS, MarkJob, Placement
from insitu.services.common import Progress
from insitu.services.height import load_height_calibration
from insitu.services.serials import save_job


@dataclass(frozen=True)
class OpenedProject:
    """A project read, with the ``cloud`` and ``height_cal`` it names loaded (or None)."""

    project: Project
    cloud: PointCloud | None
    height_cal: HeightCalibration | None


def open_project(path: str | Path, progress: Progress | None = None) -> OpenedProject:
    """Read a project and what it names (cloud, height calibration)."""
    project = read_project(path, Placement, PROJECTIONS)
    cloud = read_ply(project.cloud) if project.cloud is not None else None
    cal = (load_height_calibration(project.height_cal, progress)
           if project.height_cal is not None else None)
    return OpenedProject(project, cloud, cal)


def save_project(path: str | Path, project: Project, cloud: PointCloud | None,
                 job: MarkJob | None) -> Project:
    """Write the cloud (when it is not on disk yet) and the job beside ``path``, then the
    project file; returns the project as written (with those paths)."""
    if cloud is not None and project.cloud is None:
        project = replace(project, cloud=beside(path, ".cloud.ply"))
        write_ply(project.cloud, cloud)
    if job is not None:
        project = replace(project, job=beside(path, ".job.json"))
        save_job(project.job, job)
    else:
        project = replace(project, job=None)
    write_project(path, project)
    return project
