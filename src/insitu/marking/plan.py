"""From placed polylines and a measured cloud to a checked mark job, in one call."""

from __future__ import annotations

import numpy as np

from insitu.formats.pointcloud import PointCloud
from insitu.marking.checks import Limits, check_projection
from insitu.marking.job import LaserOverride, LaserParams, MarkJob, Timing, make_job
from insitu.marking.modes import project
from insitu.marking.project import Projection


def plan_job(polylines: list[np.ndarray], cloud: PointCloud | np.ndarray, limits: Limits,
             mode: str = "planar", laser: LaserParams | None = None,
             overrides: dict[int, LaserOverride] | None = None, timing: Timing | None = None,
             anchor=None, direction_deg: float | None = None, step_mm: float | None = None
             ) -> tuple[MarkJob, Projection]:
    """Project ``polylines`` ((N, 2) world mm each) onto ``cloud`` (``mode``: a key of
    :data:`~insitu.marking.modes.PROJECTIONS`; ``anchor`` (2,) mm: the point wrap keeps in
    place, e.g. the --at centre; ``direction_deg``: wrap's unroll direction, default the
    least-stretch one), refuse it
    (SafetyError) outside the field or focus range or over a hole or a wall, and make the
    job. Returns the job and the projection (max_stretch, step, per-point support)."""
    proj = project(polylines, cloud, mode, anchor=anchor, direction_deg=direction_deg,
                   step_mm=step_mm)
    check_projection(proj, limits)
    return make_job(proj.paths, laser, overrides, timing), proj
