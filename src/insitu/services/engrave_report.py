"""An engraving's report: each measurement as the record keeps it, and the pictures
(matplotlib, no display): the depth map over the pocket's cells (cells the camera cannot see
crossed, wall cells dotted) and the histogram of the floor's depths against the target, each
written atomically."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from insitu.formats.atomic import atomic_write_bytes
from insitu.marking.engrave_depth import (
    HIDDEN,
    OUTSIDE,
    STATES,
    UNMEASURED,
    WALL,
    DepthMap,
    PocketCells,
)
from insitu.marking.engrave_plan import CellHistory, Learnt


def _save(fig, path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write_bytes(path, buf.getvalue())


def depth_picture(path: Path, dm: DepthMap, target_mm: float, title: str,
                  centre: str = "target") -> None:
    """The depth map (µm) of ``dm``'s cells, ``target_mm`` in the middle of the colour scale
    (named ``centre`` on it)."""
    depth_pictures(path, [(dm, target_mm, title)], centre=centre)


def depth_pictures(path: Path, maps: list[tuple[DepthMap, float, str]], title: str = "",
                   centre: str = "target") -> None:
    """The depth maps (µm) side by side, each (map, the value in the middle of its colour
    scale mm, its title), under ``title``: e.g. a pocket measured from each pass of a crossed
    scan."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6.4 * len(maps), 4.8))
    for k, (dm, target_mm, panel) in enumerate(maps):
        _depth_panel(fig, fig.add_subplot(1, len(maps), k + 1), dm, target_mm, panel, centre)
    if title:
        fig.suptitle(title, fontsize=10)
    _save(fig, path)


def _depth_panel(fig, ax, dm: DepthMap, target_mm: float, title: str, centre: str) -> None:
    c = dm.cells
    ny, nx = c.shape
    extent = (c.origin[0] - c.cell_mm / 2, c.origin[0] + (nx - 0.5) * c.cell_mm,
              c.origin[1] - c.cell_mm / 2, c.origin[1] + (ny - 0.5) * c.cell_mm)
    depth = np.where(dm.state == OUTSIDE, np.nan, dm.depth) * 1e3
    span = max(25.0, float(np.nanmax(np.abs(depth - target_mm * 1e3))) if np.isfinite(
        depth).any() else 25.0)
    im = ax.imshow(depth, origin="lower", extent=extent, cmap="coolwarm_r",
                   vmin=target_mm * 1e3 - span, vmax=target_mm * 1e3 + span,
                   interpolation="nearest")
    gx, gy = c.centres()
    for state, marker, label in ((HIDDEN, "x", "hidden by a wall"),
                                 (UNMEASURED, "+", "not measured"), (WALL, ".", "wall band")):
        m = dm.state == state
        if m.any():
            ax.plot(gx[m], gy[m], marker, color="k", ms=3, ls="", label=label)
    if (dm.state >= HIDDEN).any() or (dm.state == WALL).any():
        ax.legend(loc="upper right", fontsize=7)
    fig.colorbar(im, ax=ax, label=f"depth, µm ({centre} {target_mm * 1e3:g})")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")


def histogram_picture(path: Path, dm: DepthMap, target_mm: float, tolerance_mm: float) -> None:
    """The floor points' depths (µm) with the target and ± ``tolerance_mm``."""
    from matplotlib.figure import Figure

    d = dm.floor[:, 2] * 1e3
    fig = Figure(figsize=(6.4, 3.6))
    ax = fig.add_subplot()
    if len(d):
        lo, hi = np.percentile(d, [0.5, 99.5])
        ax.hist(np.clip(d, lo, hi), bins=60, color="#4070a0")
    for v, style in ((target_mm, "-"), (target_mm - tolerance_mm, ":"),
                     (target_mm + tolerance_mm, ":")):
        ax.axvline(v * 1e3, color="k", ls=style, lw=1)
    mean, sem = dm.mean_depth()
    ax.set_title(f"floor depth: mean {mean * 1e3:.1f} ± {sem * 1e3:.1f} µm, point σ "
                 f"{dm.point_sigma * 1e3:.1f} µm ({len(d)} points)", fontsize=9)
    ax.set_xlabel("depth, µm")
    ax.set_ylabel("points")
    _save(fig, path)


def measure_summary(round_no: int, dm: DepthMap, learnt: Learnt, history: CellHistory,
             target: float, frames: int, seconds: float) -> dict:
    """A measurement as the record keeps it (mm; NaN as None)."""
    mean, sem = dm.mean_depth()
    seen = np.isin(dm.state, (0, 1))
    err = (dm.depth - target)[dm.state == 0]
    half = 0.5 * float(np.median(history.rate[seen])) if seen.any() else 0.0

    def num(v):
        return None if v is None or not np.isfinite(v) else round(float(v), 6)
    return {"round": round_no, "passes_mean": num(history.passes[dm.state >= 0].mean()),
            "mean_mm": num(mean), "sem_mm": num(sem), "point_sigma_mm": num(dm.point_sigma),
            "top_rms_mm": num(dm.top_rms), "rate_mm": num(learnt.rate_mm),
            "rate_sem_mm": num(learnt.rate_sem_mm), "rate_spread_mm": num(learnt.spread_mm),
            "rate_cells": learnt.cells,
            "cells": {name: dm.count(i) for i, name in enumerate(STATES)},
            "at_depth": int((np.abs(err) <= half).sum()), "short": int((err < -half).sum()),
            "over": int((err > half).sum()),
            "cell_p95_mm": num(np.percentile(np.abs(err), 95)) if len(err) else None,
            "frames": frames, "scan_s": round(seconds, 3),
            "hidden_at_mm": centres(dm.cells, dm.state == 2)}


def centres(cells: PocketCells, mask: np.ndarray) -> list[list[float]]:
    """The world x, y (mm) of the cells where ``mask``."""
    gx, gy = cells.centres()
    return np.round(np.column_stack([gx[mask], gy[mask]]), 3).tolist()
