"""A pocket measured on the station, as an engraving measures it between rounds: a local scan
of lines across the pocket and the top around it, their centres found across the line only
(:data:`DEPTH_CENTRES`: nothing smoothed along it, so a wall's step is not carried onto the
floor), the depth mapped per cell against the top of the same lines
(:func:`insitu.marking.engrave_depth.measure_depth`), the cells the camera or the beam
cannot reach past a wall told apart."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from insitu.formats.calibration import HeightCalibration
from insitu.marking.engrave_depth import (
    DepthMap,
    DepthSettings,
    Outline,
    PocketCells,
    measure_depth,
)
from insitu.marking.engrave_walls import viewpoints
from insitu.services.common import Progress
from insitu.services.height import centre_settings
from insitu.services.scan import scan_live
from insitu.services.station import Station
from insitu.vision.extract import CentreSettings

DEPTH_CENTRES = dict(method="gaussian", smooth_half_window=0, smooth_grains=0.0)
"""How a depth scan finds line centres: across the line only (a Gaussian per row), nothing
smoothed along it, so a wall's step is not carried onto the floor beside it."""


def depth_centres(height_cal: HeightCalibration | None) -> CentreSettings:
    """The centre finding of a depth scan: the height calibration's (None: the default)
    with :data:`DEPTH_CENTRES` over it."""
    base = centre_settings(height_cal).to_dict() if height_cal is not None else {}
    return CentreSettings(**{**base, **DEPTH_CENTRES})


LINES_ALONG = np.array([0.0, 1.0])
"""The direction a depth scan's lines run in (world x, y): along y, stepped across x."""


@dataclass(frozen=True)
class PocketScan:
    """A pocket's depth ``map`` and the ``frames`` its scan took."""

    map: DepthMap
    frames: int


def pocket_scan_region(region, settings: DepthSettings) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) mm a depth scan of the pocket ``region`` (shapely, world mm) covers:
    the lines (along y) past the wall band on each side in x, the top ring in y."""
    x0, y0, x1, y1 = region.bounds
    band = settings.wall_band_mm + 0.3
    return (x0 - band, x1 + band, y0 - settings.ring_mm, y1 + settings.ring_mm)


def measure_pocket(station: Station, region, settings: DepthSettings | None = None,
                   spacing_mm: float = 0.1, height_cal: HeightCalibration | None = None,
                   cancel: threading.Event | None = None, progress: Progress | None = None,
                   outline: Outline | None = None, cells: PocketCells | None = None,
                   expected_mm: np.ndarray | None = None) -> PocketScan:
    """Scan the pocket ``region`` on ``station`` (lines ``spacing_mm`` apart; heights by
    ``height_cal``, None: the light plane alone) and map its depth (``outline``, ``cells``,
    ``expected_mm``: as :func:`~insitu.marking.engrave_depth.measure_depth` takes them).
    Cancelled when ``cancel`` is set; MeasurementError when too few points land on the top
    or the floor."""
    s = settings or DepthSettings()
    scan = scan_live(station, spacing_mm, pocket_scan_region(region, s), height_cal,
                     centres=depth_centres(height_cal), cancel=cancel, progress=progress,
                     room_light=False)
    dm = measure_depth(scan.cloud.points, scan.cloud.attributes["line"], region, s, outline,
                       cells, viewpoints(station.rig), expected_mm)
    return PocketScan(dm, scan.summary.frames)


def scan_pocket(station: Station, region, settings: DepthSettings | None = None,
                spacing_mm: float = 0.1, height_cal: HeightCalibration | None = None,
                cancel: threading.Event | None = None,
                progress: Progress | None = None) -> DepthMap:
    """The depth map of :func:`measure_pocket` (the pocket on its own, no engraving's
    cells)."""
    return measure_pocket(station, region, settings, spacing_mm, height_cal, cancel,
                          progress).map
