"""Read the marks back: the side camera's image of the marked part rectified onto the
measured surface, each code decoded and graded, each mark's placement against the plan — the
use case behind ``insitu mark --run --inspect``, ``insitu inspect``, the GUI's Mark dock and
``produce``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from insitu.errors import FormatError
from insitu.formats.pointcloud import PointCloud
from insitu.geometry.camera import CameraModel
from insitu.marking import Placement
from insitu.marking.readback import MarkReading, read_mark
from insitu.marking.readback_picture import readback_picture
from insitu.marking.surface import Surface
from insitu.patterns.vector import BEAM_MM
from insitu.services.mark import save_image
from insitu.services.plan import MarkPlan
from insitu.services.room_light import station_room_light

if TYPE_CHECKING:
    from insitu.services.station import Station

_REGION_MARGIN_MM = 5.0


@dataclass(frozen=True)
class ReadBack:
    """The marks read back: ``readings`` (one :class:`~insitu.marking.readback.MarkReading`
    per planned pattern: text, decoded, ``ok``, ``offset_mm``, ``grades``, the rectified
    ``picture``), the camera's raw ``image`` (H, W) and the read-back ``picture`` (BGR uint8:
    each mark rectified, the plan over it, what was read)."""

    readings: tuple[MarkReading, ...]
    image: np.ndarray
    picture: np.ndarray

    @property
    def ok(self) -> bool:
        """Every code decoded to its planned text (and every drawing found in place)."""
        return all(r.ok for r in self.readings)


def read_back_image(image: np.ndarray, camera: CameraModel, cloud: PointCloud,
                    plans: Sequence[MarkPlan], beam_mm: float = BEAM_MM) -> ReadBack:
    """Read each planned mark of ``plans`` back from ``image`` (the camera's frame of the
    marked part) through ``camera`` (the calibrated side camera) onto ``cloud`` (the
    measured surface the plans were projected on). FormatError when the image is not the
    camera's size."""
    img = np.asarray(image)
    if img.shape[:2] != (camera.height, camera.width):
        raise FormatError(f"the image is {img.shape[1]}×{img.shape[0]} px, the camera "
                          f"{camera.width}×{camera.height} px: not this camera's frame")
    readings = []
    for plan in plans:
        x0, y0, x1, y1 = plan.pattern.bounds()
        m = _REGION_MARGIN_MM
        surf = Surface(cloud, region=(x0 - m, x1 + m, y0 - m, y1 + m))
        readings.append(read_mark(img, camera, surf, plan.pattern, plan.projection,
                                  [p.points for p in plan.job.paths], beam_mm))
    return ReadBack(tuple(readings), img, readback_picture(readings))


def read_back(station: Station, plans: Sequence[MarkPlan], cloud: PointCloud,
              image: np.ndarray | None = None, beam_mm: float = BEAM_MM) -> ReadBack:
    """:func:`read_back_image` with the station's camera: its model as calibrated, and a
    frame under the room light now (the laser off, auto-exposed) unless ``image`` is given."""
    if image is None:
        image = station_room_light(station).image
    return read_back_image(image, station.rig.camera, cloud, plans, beam_mm)


def raw_path(picture_path: str | Path) -> Path:
    """Where the raw camera frame goes beside the read-back picture: ``NAME.raw.png``."""
    p = Path(picture_path)
    return p.with_name(p.stem + ".raw.png")


def save_read_back(path: str | Path, result: ReadBack) -> Path:
    """Write the read-back picture to ``path`` and the raw frame beside it
    (:func:`raw_path`), both atomically. Returns the raw frame's path."""
    raw = raw_path(path)
    save_image(raw, result.image)
    save_image(path, result.picture)
    return raw


def table_rows(result: ReadBack) -> list[list[str]]:
    """One row per mark: name, planned text, decoded, = plan?, offset u, v mm, share of it
    the camera sees, grade."""
    rows = []
    for r in result.readings:
        off = "not found" if r.offset_mm is None else "{:+.3f}, {:+.3f}".format(*r.offset_mm)
        rows.append([r.name, "-" if r.text is None else r.text,
                     "-" if r.text is None else ("NOT decoded" if r.decoded is None
                                                 else r.decoded),
                     "yes" if r.ok else "NO", off, f"{r.seen:.0%}",
                     "-" if r.grades is None else r.grades.summary()])
    return rows


def as_marked(placement: Placement, job_path: Path | None) -> Placement:
    """``placement`` as its job marked it: a pattern with fields (``{serial}``, ``{date}``, …)
    rendered with the job's recorded variable data (FormatError naming the pattern without a
    job, or a job without that record)."""
    from insitu.marking import read_job
    from insitu.patterns.fields import is_template
    from insitu.services.serials import job_variables, render_placement

    if not is_template(placement.pattern):
        return placement
    if job_path is None:
        raise FormatError(f"pattern {placement.pattern!r} has fields: name the job it was "
                          "marked with, whose texts say what was marked", field="pattern")
    values = job_variables(read_job(job_path), job_path)
    if values is None:
        raise FormatError(f"{job_path}: no variable_data: not the job of a pattern with fields")
    return render_placement(placement, values.variables())
