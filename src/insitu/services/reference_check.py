"""Is a scan fit to be a recipe's reference? It must show the part's whole top: a part cut
by the scan's edge, or a top with large unmeasured strips (shadows beside its walls, a
coarse scan), is located poorly or not at all on every part that follows ("part not found",
"only partly in the scan"). Measured from the scan alone — no model of the part is needed:
the part is what stands above the table (:func:`insitu.locate.reference.find_table`); its
footprint seen from above (holes filled) against the area its points cover."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.errors import MeasurementError
from insitu.locate.reference import above_table, find_table

CELL_MM = 0.25
WARN_BELOW = 0.95
"""A top measured less than this is a warning: parts may be located less surely."""
REFUSE_BELOW = 0.8
"""A top measured less than this is refused (locating needs 80 % of the reference's top
seen in each part's scan: a reference missing more cannot vouch for it)."""
BAND_MM = 0.5
CLOSE_MM = 3.0
"""Gaps narrower than this inside the part's outline are holes in the top, not its edge."""


@dataclass(frozen=True)
class ReferenceCheck:
    """``coverage``: the share of the part's footprint its points cover (0 … 1);
    ``cut``: the sides ("x−", "x+", "y−", "y+") where the part reaches the scan's edge;
    ``spacing_mm``: the scan's line spacing; ``level``: "ok", "warning" or "refused";
    ``text``: one line saying what and what to do."""

    coverage: float
    cut: tuple[str, ...]
    spacing_mm: float
    level: str
    text: str


def line_spacing(points: np.ndarray, lines: np.ndarray | None) -> float:
    """The scan's line spacing, mm: the median distance from each line's centre to the
    nearest other's (0.5 without line numbers)."""
    if lines is None or len(np.unique(lines)) < 3:
        return 0.5
    ids, inv = np.unique(lines, return_inverse=True)
    centres = np.stack([np.bincount(inv, points[:, k]) / np.bincount(inv) for k in (0, 1)], 1)
    d = np.hypot(*(centres[:, None] - centres[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    return float(np.clip(np.median(d.min(1)), 0.05, 5.0))


def check_reference(points: np.ndarray, lines: np.ndarray | None = None) -> ReferenceCheck:
    """The check of a scan ``points`` (N, 3) mm (``lines``: (N,) the scan line of each
    point, as insitu's clouds keep them). MeasurementError when no part stands above the
    table."""
    pts = np.asarray(points, float)
    table = find_table(pts)
    part = pts[above_table(pts, table, BAND_MM)] if table is not None else pts[:0]
    if len(part) < 100:
        raise MeasurementError("reference: no part above the table in the scan: scan the "
                               "part on the table")
    spacing = line_spacing(pts, None if lines is None else np.asarray(lines))
    lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
    shape = (int((hi[1] - lo[1]) / CELL_MM) + 3, int((hi[0] - lo[0]) / CELL_MM) + 3)
    px = ((part[:, :2] - lo) / CELL_MM).astype(int) + 1
    seen = np.zeros(shape, np.uint8)
    seen[px[:, 1], px[:, 0]] = 1
    reach = max(int(round(0.75 * spacing / CELL_MM)), 1)       # a line covers its strip
    seen = cv2.dilate(seen, cv2.getStructuringElement(cv2.MORPH_ELLIPSE,
                                                      (2 * reach + 1, 2 * reach + 1)))
    k = max(int(round(CLOSE_MM / CELL_MM)), 3) | 1
    outline = cv2.morphologyEx(seen, cv2.MORPH_CLOSE,
                               cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    flood = outline.copy()
    cv2.floodFill(flood, np.zeros((shape[0] + 2, shape[1] + 2), np.uint8), (0, 0), 2)
    footprint = flood != 2
    coverage = float((seen.astype(bool) & footprint).sum() / max(footprint.sum(), 1))
    part_lo, part_hi = part[:, :2].min(0), part[:, :2].max(0)
    edge = spacing + BAND_MM
    cut = tuple(name for name, gap in (("x−", part_lo[0] - lo[0]), ("x+", hi[0] - part_hi[0]),
                                       ("y−", part_lo[1] - lo[1]), ("y+", hi[1] - part_hi[1]))
                if gap < edge)
    return _verdict(coverage, cut, spacing)


def _verdict(coverage: float, cut: tuple[str, ...], spacing: float) -> ReferenceCheck:
    share = f"the scan shows {coverage:.0%} of the part's top"
    if cut:
        return ReferenceCheck(coverage, cut, spacing, "refused",
                              f"reference: the part reaches the scan's edge at "
                              f"{', '.join(cut)}: scan the whole part with a margin around it "
                              f"({share})")
    if coverage < REFUSE_BELOW:
        return ReferenceCheck(coverage, cut, spacing, "refused",
                              f"reference: {share} (at least {REFUSE_BELOW:.0%} needed): "
                              "scan it finer, crossed, or use the part's CAD mesh")
    if coverage < WARN_BELOW:
        return ReferenceCheck(coverage, cut, spacing, "warning",
                              f"reference: {share}: parts may be located less surely; a finer "
                              "or crossed scan, or the part's CAD mesh, covers more")
    return ReferenceCheck(coverage, cut, spacing, "ok", f"reference: {share}")
