"""A pocket's depth as the operator sees it (no Qt): the measured cloud against the top around
a placed pattern (:func:`measure_pocket`, :func:`insitu.marking.engrave_depth.measure_depth`),
its numbers in words (:class:`DepthSummary`: the mean depth, the band 95 % of the measured
cells lie in, the cells hidden by walls and those not measured, counted) and its picture
(:func:`depth_picture`: the cells coloured by depth with a colour bar in mm, the hidden cells
hatched, the cells not measured grey, the outline over them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.errors import MeasurementError
from insitu.formats.pointcloud import PointCloud
from insitu.marking.engrave_depth import (
    HIDDEN,
    MEASURED,
    STATES,
    UNMEASURED,
    WALL,
    DepthMap,
    DepthSettings,
    measure_depth,
)
from insitu.marking.engrave_walls import viewpoints

HIDDEN_COLOUR = "0.8"
UNMEASURED_COLOUR = "0.55"
MIN_SPAN_MM = 0.005
"""The colour scale spans at least ± this: a flat floor's noise is not blown up to the whole
scale."""


def pocket_region(plan, name: str):
    """The filled region (shapely, world mm) of a placement's checked ``plan``
    (:class:`insitu.services.plan.MarkPlan`); MeasurementError naming ``name`` when it has
    none (a pattern of lines only)."""
    region = plan.pattern.to_shapely()
    if region.is_empty or region.area <= 0:
        raise MeasurementError(f"pattern {name}: no filled area, so no pocket to measure; "
                               "a depth map needs a filled shape")
    return region


def measure_pocket(cloud: PointCloud, region, rig=None,
                   settings: DepthSettings | None = None) -> DepthMap:
    """The depth map of the pocket ``region`` in the scanned ``cloud`` (its points and scan
    lines) against the top around it; ``rig`` (a RigModel, None: not known): the cells its
    camera or beam cannot reach past a wall are told apart as hidden. MeasurementError when
    the cloud has no scan lines or too few points on the top or the floor."""
    line = cloud.attributes.get("line")
    if line is None:
        raise MeasurementError("the cloud has no scan lines (its 'line' attribute): scan the "
                               "part to measure a pocket's depth")
    return measure_depth(cloud.points, np.asarray(line), region, settings or DepthSettings(),
                         viewpoints=None if rig is None else viewpoints(rig))


@dataclass(frozen=True)
class DepthSummary:
    """A depth map's numbers (mm): ``mean`` and its ``sem`` (the floor's points), ``band``:
    the 2.5 and 97.5 percentiles of the measured cells' depths, ``counts`` per state name of
    :data:`STATES`; with a ``target``, ``p95``: 95 % of the measured cells lie within ± it."""

    mean: float
    sem: float
    band: tuple[float, float] | None
    counts: dict[str, int]
    target: float | None = None
    p95: float | None = None

    @classmethod
    def of(cls, dm: DepthMap, target_mm: float | None = None) -> DepthSummary:
        mean, sem = dm.mean_depth()
        cells = dm.depth[dm.state == MEASURED]
        cells = cells[np.isfinite(cells)]
        band = (tuple(float(v) for v in np.percentile(cells, [2.5, 97.5]))
                if len(cells) else None)
        p95 = (float(np.percentile(np.abs(cells - target_mm), 95))
               if target_mm is not None and len(cells) else None)
        return cls(mean, sem, band, {n: dm.count(i) for i, n in enumerate(STATES)},
                   target_mm, p95)

    def lines(self, rig_known: bool = True) -> list[str]:
        """The summary in words, one line each."""
        c = self.counts
        total = sum(c.values())
        out = [f"mean depth {self.mean:.4f} mm ± {self.sem:.4f} over {c['measured']} "
               f"measured cells of {total}" if np.isfinite(self.mean) else
               "no depth: no point of the floor measured"]
        if self.band is not None:
            out.append(f"95 % of the measured cells between {self.band[0]:.4f} and "
                       f"{self.band[1]:.4f} mm deep")
        if self.p95 is not None:
            out.append(f"95 % of the measured cells within ±{self.p95:.4f} mm of the target "
                       f"{self.target:g} mm")
        out.append(f"{c['hidden']} cells hidden by the walls from the camera or the beam "
                   "(hatched)" if rig_known else
                   "cells hidden by the walls not told apart: connect the rig")
        out.append(f"{c['unmeasured']} cells not measured: too few points (grey)")
        out.append(f"{c['wall']} cells within the wall band, left out of the mean (dotted)")
        return out


def depth_picture(dm: DepthMap, region, title: str, target_mm: float | None = None,
                  size_px: tuple[int, int] = (560, 440)) -> np.ndarray:
    """(H, W, 3) uint8 BGR: the measured cells coloured by depth (mm, a colour bar; centred
    on ``target_mm`` when given), the hidden cells hatched, the cells not measured grey, the
    wall band's cells dotted, ``region``'s outline in black."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import PatchCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    c = dm.cells
    ny, nx = c.shape
    h = c.cell_mm / 2
    extent = (c.origin[0] - h, c.origin[0] + (nx - 0.5) * c.cell_mm,
              c.origin[1] - h, c.origin[1] + (ny - 0.5) * c.cell_mm)
    shown = np.where(np.isin(dm.state, (MEASURED, WALL)), dm.depth, np.nan)
    finite = shown[np.isfinite(shown)]
    lo, hi = (float(finite.min()), float(finite.max())) if len(finite) else (0.0, 0.0)
    mid = target_mm if target_mm is not None else (lo + hi) / 2
    span = max(abs(lo - mid), abs(hi - mid), MIN_SPAN_MM)
    lo, hi = mid - span, mid + span
    fig = Figure(figsize=(size_px[0] / 100, size_px[1] / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    im = ax.imshow(shown, origin="lower", extent=extent, cmap="viridis_r", vmin=lo, vmax=hi,
                   interpolation="nearest")
    gx, gy = c.centres()
    for state, colour, hatch, label in ((HIDDEN, HIDDEN_COLOUR, "////", "hidden by a wall"),
                                        (UNMEASURED, UNMEASURED_COLOUR, None, "not measured")):
        m = dm.state == state
        if m.any():
            boxes = [Rectangle((x - h, y - h), c.cell_mm, c.cell_mm)
                     for x, y in zip(gx[m], gy[m])]
            ax.add_collection(PatchCollection(boxes, facecolor=colour, edgecolor="0.3",
                                              hatch=hatch, linewidth=0.0,
                                              label=f"{label} ({int(m.sum())})"))
    wall = dm.state == WALL
    if wall.any():
        ax.plot(gx[wall], gy[wall], ".", color="k", ms=1.5, ls="",
                label=f"wall band ({int(wall.sum())})")
    for ring in _rings(region):
        ax.plot(ring[:, 0], ring[:, 1], "-", color="k", lw=0.8)
    if (dm.state >= HIDDEN).any() or wall.any():
        ax.legend(loc="upper right", fontsize=7, framealpha=0.8)
    bar = fig.colorbar(im, ax=ax, label="depth, mm" + (f" (target {target_mm:g})"
                                                        if target_mm is not None else ""))
    bar.formatter.set_useOffset(False)
    bar.update_ticks()
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    fig.tight_layout()
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    return np.ascontiguousarray(rgba[:, :, 2::-1])


def _rings(region) -> list[np.ndarray]:
    """The outline of a shapely (multi)polygon: (K, 2) arrays, exteriors and holes."""
    polys = getattr(region, "geoms", [region])
    out = []
    for p in polys:
        if hasattr(p, "exterior"):
            out.append(np.asarray(p.exterior.coords))
            out += [np.asarray(r.coords) for r in p.interiors]
    return out

