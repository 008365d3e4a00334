"""The scan field: the rectangle (width, height) mm on z = 0, centred on the origin, that the
beam may reach — and the one check of points against it."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from insitu.errors import SafetyError

_TOL_MM = 1e-9


def check_in_field(xy, field_size_mm, describe: Callable[[int, str], str], *, at=None,
                   worst: bool = False, more: bool = False) -> None:
    """Refuse points outside the scan field.

    ``xy``: (N, 2) mm on z = 0 (e.g. where the beams cross it); a point is outside when
    |x| > width / 2 or |y| > height / 2 (by more than 1e-9 mm), or when it is not finite. For
    the first such point i (``worst``: the one farthest out, relative to the half field)
    raises ``SafetyError(describe(i, "±w/2 × ±h/2 mm"))`` (``more``: followed by
    " (and K more points)") with ``where_mm`` = ``at[i, :2]`` (``at``: (N, ≥ 2) world mm,
    default ``xy``)."""
    pts = np.asarray(xy, float).reshape(-1, 2)
    half = np.asarray(field_size_mm, float) / 2
    finite = np.isfinite(pts).all(1)
    with np.errstate(invalid="ignore"):
        out = ~finite | (np.abs(pts) > half + _TOL_MM).any(1)
    if not out.any():
        return
    if worst:
        i = int(np.argmax(np.where(finite, np.max(np.abs(pts) / half, axis=1), np.inf)))
    else:
        i = int(np.argmax(out))
    n = int(out.sum()) - 1
    tail = f" (and {n} more points)" if more and n else ""
    place = np.asarray(at if at is not None else pts, float)[i]
    raise SafetyError(describe(i, f"±{half[0]:g} × ±{half[1]:g} mm") + tail,
                      where_mm=(place[0], place[1]))
