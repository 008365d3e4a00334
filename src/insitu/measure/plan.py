"""The scan plan: which lines the head draws over a region, and whether the region can be
scanned."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from insitu.errors import MeasurementError


def scan_lines(region: Sequence[float], spacing: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Lines along y over region (x0, x1, y0, y1), mm, one every ``spacing`` mm along x."""
    x0, x1, y0, y1 = map(float, region)
    n = int(np.floor((x1 - x0) / spacing + 1e-9)) + 1
    return [(np.array([x, y0]), np.array([x, y1])) for x in x0 + spacing * np.arange(n)]


def check_region(region: Sequence[float], field_size_mm: Sequence[float]) -> None:
    """MeasurementError unless region (x0, x1, y0, y1), mm, is a rectangle inside the scan
    field of ``field_size_mm`` (width, height) centred on the origin."""
    x0, x1, y0, y1 = region
    half = np.asarray(field_size_mm, float) / 2
    if not (x0 < x1 and y0 < y1):
        raise MeasurementError(f"--region {x0:g} {x1:g} {y0:g} {y1:g}: expected X0 < X1 and Y0 < Y1")
    if max(abs(x0), abs(x1)) > half[0] or max(abs(y0), abs(y1)) > half[1]:
        raise MeasurementError(f"--region {x0:g} {x1:g} {y0:g} {y1:g}: outside the scan field "
                               f"±{half[0]:g} × ±{half[1]:g} mm")
