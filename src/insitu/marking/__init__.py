"""Marking: project placed patterns onto the measured surface, check them, make the mark job
(docs/formats.md, mark job) and drive the scan head with it.

    job, proj = plan_job(polylines, cloud, Limits.of(head_config), mode="planar")
    write_job("job.json", job)
    run_job(job, GalvoDriver.from_config(head_config), controller, progress_path_for("job.json"))
"""

from insitu.marking.checks import Limits, check_projection, check_targets
from insitu.marking.driver import GalvoDriver, preview_outlines
from insitu.marking.job import (
                                LaserOverride,
                                LaserParams,
                                MarkJob,
                                MarkPath,
                                TimeEstimate,
                                Timing,
                                estimate_time,
                                make_job,
                                path_seconds,
                                read_job,
                                with_pen,
                                write_job,
)
from insitu.marking.journal import JournalSummary, journal_path_for, read_journal
from insitu.marking.modes import PROJECTIONS, ProjectionMode, project, projection_mode
from insitu.marking.placement import Placement
from insitu.marking.plan import plan_job
from insitu.marking.project import Projection, densify, project_planar, project_wrap
from insitu.marking.run import (
                                CUT_CHOICES,
                                RunResult,
                                history,
                                progress_path_for,
                                read_progress,
                                run_job,
                                run_preview,
)
from insitu.marking.surface import Surface, SurfaceSample

__all__ = [
    "CUT_CHOICES", "JournalSummary", "history", "journal_path_for", "read_journal",
    "GalvoDriver", "LaserOverride", "LaserParams", "Limits", "MarkJob", "MarkPath", "PROJECTIONS",
    "Placement", "Projection", "ProjectionMode", "RunResult", "Surface", "SurfaceSample", "TimeEstimate",
    "Timing", "check_projection", "check_targets", "densify", "estimate_time", "make_job",
    "plan_job", "preview_outlines", "progress_path_for", "project", "project_planar",
    "project_wrap", "projection_mode", "read_job", "read_progress", "run_job",
    "run_preview", "path_seconds", "with_pen", "write_job",
]
