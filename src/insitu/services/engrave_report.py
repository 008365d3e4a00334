"""The pictures of an engraving's report (matplotlib, no display): the depth map over the
pocket's cells (cells the camera cannot see crossed, wall cells dotted) and the histogram of
the floor's depths against the target, each written atomically."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from insitu.formats.atomic import atomic_write_bytes
from insitu.marking.engrave_depth import HIDDEN, OUTSIDE, UNMEASURED, WALL, DepthMap


def _save(fig, path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    atomic_write_bytes(path, buf.getvalue())


def depth_picture(path: Path, dm: DepthMap, target_mm: float, title: str) -> None:
    """The depth map (µm) of ``dm``'s cells, the target in the middle of the colour scale."""
    from matplotlib.figure import Figure

    c = dm.cells
    ny, nx = c.shape
    extent = (c.origin[0] - c.cell_mm / 2, c.origin[0] + (nx - 0.5) * c.cell_mm,
              c.origin[1] - c.cell_mm / 2, c.origin[1] + (ny - 0.5) * c.cell_mm)
    depth = np.where(dm.state == OUTSIDE, np.nan, dm.depth) * 1e3
    span = max(25.0, float(np.nanmax(np.abs(depth - target_mm * 1e3))) if np.isfinite(
        depth).any() else 25.0)
    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.add_subplot()
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
    fig.colorbar(im, ax=ax, label=f"depth, µm (target {target_mm * 1e3:g})")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    _save(fig, path)


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
