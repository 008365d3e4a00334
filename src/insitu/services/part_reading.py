"""What production reads of a marked part: the read-back of its marks as one value for the
log (:class:`PartReading`), and the check that fails a part whose marks are not the plan or
lie beyond the recipe's tolerance from their planned place (:func:`reading_fault`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from insitu.formats.pointcloud import PointCloud

if TYPE_CHECKING:
    from insitu.services.station import Station


@dataclass(frozen=True)
class PartReading:
    """What the camera read of the marked part, one value for the log: ``decoded`` texts
    (" | " between codes; None: no code read), whether every mark is what was planned
    (``ok``), the worst code's print ``grade`` (A … F) and the largest ``offset_mm`` of a
    mark from its planned place."""

    decoded: str | None = None
    ok: bool | None = None
    grade: str | None = None
    offset_mm: float | None = None


ReadBackFn = Callable[["Station", list, PointCloud, Path], PartReading]


def read_part(station: Station, plans: list, cloud: PointCloud, picture: Path) -> PartReading:
    """Read the part's marks back (:func:`insitu.services.inspect.read_back`: the camera's
    frame rectified onto the measured surface, each code decoded and graded) and write the
    read-back picture to ``picture`` (the raw frame beside it)."""
    from insitu.services.inspect import read_back, save_read_back
    from insitu.vision.dpm_grade import letter

    got = read_back(station, plans, cloud)
    save_read_back(picture, got)
    texts = [r.decoded for r in got.readings if r.text is not None and r.decoded is not None]
    grades = [r.grades.overall for r in got.readings if r.grades is not None]
    offsets = [float(np.hypot(*r.offset_mm)) for r in got.readings if r.offset_mm is not None]
    return PartReading(" | ".join(texts) if texts else None, got.ok,
                       letter(min(grades)) if grades else None,
                       max(offsets) if offsets else None)


def reading_fault(got: PartReading, tolerance_mm: float) -> str | None:
    """Why the part fails its read-back, in one line (None: it passes): a mark that is not
    the plan (a code not read, or read as another text), or a mark whose offset from its
    planned place exceeds ``tolerance_mm`` (the recipe's ``read.offset_tolerance_mm``). The
    offset is measured in the frame the part was located in, so it is where the mark lies
    on the part against the recipe's place: the head's field correction and the marking."""
    if got.ok is False:
        read = "no code read" if got.decoded is None else f"read {got.decoded!r}"
        return f"read-back: the marks are not the plan ({read}); set the part aside"
    if got.offset_mm is not None and got.offset_mm > tolerance_mm:
        return (f"read-back: a mark lies {got.offset_mm:.3f} mm from its planned place, beyond "
                f"read.offset_tolerance_mm {tolerance_mm:g} mm; set the part aside and check "
                "the head's field correction")
    return None
