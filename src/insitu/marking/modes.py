"""The projection modes: how placed polylines meet the measured surface. :data:`PROJECTIONS`
is the one list of them — ``insitu mark --mode``, the Place dock's mode box and the project
files read it. A new mode is a module with its projector and one entry here."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from insitu.errors import FormatError
from insitu.formats.validation import one_of
from insitu.marking.project import Projection, project_planar, project_wrap


@dataclass(frozen=True)
class ProjectionMode:
    """``project(polylines, cloud, *, anchor, direction_deg, step_mm)`` → :class:`Projection`:
    polylines (N, 2) world mm each onto a PointCloud, (N, 3) mm array or Surface; ``anchor``
    (2,) mm: the point that stays put, ``direction_deg``: an unroll direction (a mode may
    ignore both), ``step_mm``: densification step (None: the cloud's spacing).
    ``description``: one line (CLI help, GUI tooltip); ``stretches``: the projection reports
    its metric distortion (``Projection.max_stretch``)."""

    project: Callable[..., Projection]
    description: str
    stretches: bool = False


PROJECTIONS: dict[str, ProjectionMode] = {
    "planar": ProjectionMode(project_planar, "keep x, y, take z from the surface"),
    "wrap": ProjectionMode(project_wrap, "keep lengths along the surface", stretches=True),
}


def projection_mode(name: str) -> ProjectionMode:
    """The mode called ``name``; FormatError naming the choices for another."""
    if name not in PROJECTIONS:
        raise FormatError(f"mode {name!r}: expected {one_of(PROJECTIONS)}", field="mode")
    return PROJECTIONS[name]


def project(polylines, cloud, mode: str = "planar", *, anchor=None,
            direction_deg: float | None = None, step_mm: float | None = None) -> Projection:
    """Project ``polylines`` onto ``cloud`` by ``mode`` (a key of :data:`PROJECTIONS`)."""
    return projection_mode(mode).project(polylines, cloud, anchor=anchor,
                                         direction_deg=direction_deg, step_mm=step_mm)
