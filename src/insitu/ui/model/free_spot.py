"""Where a new pattern goes: on the part's top — the highest flat level of the measured
surface above the table, away from walls, holes and the patterns already placed — where a
pattern of the size asked fits, nearest the view's centre; else the flat spot with the most
room. Everything in world mm, from the cloud seen from above (no Qt)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.locate.reference import find_table

FLAT_MM = 0.3           # heights within a cell's neighbours spread less than this: flat
LEVEL_MM = 0.5          # cells this close to a level's height are on it
MARGIN_MM = 1.0         # kept from walls, holes and other patterns
MAX_CELLS = 400         # per side of the height image


@dataclass(frozen=True)
class Spot:
    """``xy`` (2,) mm where the pattern's centre goes; ``room_mm``: the radius of the free
    flat disc about it; ``z_mm``: its height."""

    xy: tuple[float, float]
    room_mm: float
    z_mm: float


def free_spot(points: np.ndarray, taken: list[np.ndarray], radius_mm: float,
              near_xy=(0.0, 0.0)) -> Spot | None:
    """The spot for a pattern needing a disc of ``radius_mm`` on the cloud ``points``
    (N, 3) mm, outside the polygons ``taken`` ((K, 2) mm each: placed patterns), nearest
    ``near_xy`` on the highest level where it fits; None for a cloud without a flat spot."""
    pts = np.asarray(points, float)
    if len(pts) < 10:
        return None
    lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
    cell = max(float((hi - lo).max()) / MAX_CELLS, 0.25)
    shape = (int((hi[1] - lo[1]) / cell) + 1, int((hi[0] - lo[0]) / cell) + 1)
    col = ((pts[:, 0] - lo[0]) / cell).astype(int)
    row = ((pts[:, 1] - lo[1]) / cell).astype(int)
    top = np.full(shape, -np.inf, np.float32)
    np.maximum.at(top, (row, col), pts[:, 2].astype(np.float32))
    measured = np.isfinite(top)
    k = np.ones((3, 3), np.uint8)
    high = cv2.dilate(np.where(measured, top, np.inf).astype(np.float32), k)
    low = cv2.erode(np.where(measured, top, -np.inf).astype(np.float32), k)
    good = measured & (high - low < FLAT_MM)         # an unmeasured neighbour is not flat
    table = find_table(pts)
    if table is not None and (good & (top > table + LEVEL_MM)).any():
        good &= top > table + LEVEL_MM              # the part, not the table around it
    mask = good.astype(np.uint8)
    for poly in taken:
        px = ((np.asarray(poly, float) - lo) / cell).round().astype(np.int32)
        cv2.fillPoly(mask, [px], 0)
    if not mask.any():
        return None
    room = cv2.distanceTransform(mask, cv2.DIST_L2, 5) * cell - MARGIN_MM
    fits = room >= radius_mm
    if fits.any():
        levels = np.where(fits, top, -np.inf)
        pick = fits & (levels >= levels.max() - LEVEL_MM)
    else:
        pick = room >= room.max() - cell
    rows, cols = np.nonzero(pick)
    xy = np.c_[lo[0] + (cols + 0.5) * cell, lo[1] + (rows + 0.5) * cell]
    i = int(np.argmin(np.hypot(*(xy - np.asarray(near_xy, float)).T)))
    r, c = rows[i], cols[i]
    return Spot((round(float(xy[i, 0]), 1), round(float(xy[i, 1]), 1)),
                max(float(room[r, c]), 0.0), float(top[r, c]))
