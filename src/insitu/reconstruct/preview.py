"""A picture of a point cloud for reports and headless runs (matplotlib, no display): the top
view coloured by height with its colour bar in mm, and beside it, when the cloud carries
``ambient``, the same view in the camera's room-light grey — what the part looks like. Axes
in mm (equal scale), a mm scale bar, the cloud named in the title.

Each panel is a raster of the top view: a cell takes the value of the nearest point within
the gap a line scan leaves between its lines (cells farther from any point stay blank).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_bytes
from insitu.formats.pointcloud import PointCloud

MAX_CELLS = 700           # cells along the longer side of a panel
PANEL_IN = 6.5            # the longer side of a panel, inches (at 150 dpi: ~1000 px)


def top_view(points: np.ndarray, values: list[np.ndarray], line: np.ndarray | None = None,
             max_cells: int = MAX_CELLS) -> tuple[list[np.ndarray], tuple[float, ...]]:
    """Rasters (rows, cols) float of each of ``values`` ((N,) each) seen from above, NaN
    where no point is near, and their extent (x0, x1, y0, y1) mm. ``points`` (N, 3) mm;
    ``line``: each point's scan-line index, to bridge the gap between lines."""
    xy = points[:, :2]
    lo, hi = xy.min(0), xy.max(0)
    cell = max(float((hi - lo).max()) / max_cells, 1e-3)
    reach = 2.5 * cell
    if line is not None and len(np.unique(line)) > 1:       # lines offset along x
        centre_x = [np.median(xy[line == k, 0]) for k in np.unique(line)]
        reach = max(reach, 0.75 * float(np.median(np.abs(np.diff(np.sort(centre_x))))))
    lo, hi = lo - cell, hi + cell
    nx, ny = (np.ceil((hi - lo) / cell).astype(int) + 1)
    gx, gy = np.meshgrid(lo[0] + cell * np.arange(nx), lo[1] + cell * np.arange(ny))
    d, idx = cKDTree(xy).query(np.column_stack([gx.ravel(), gy.ravel()]),
                               distance_upper_bound=reach, workers=-1)
    found = np.isfinite(d)
    rasters = []
    for v in values:
        r = np.full(gx.size, np.nan)
        r[found] = np.asarray(v, float)[idx[found]]
        rasters.append(r.reshape(ny, nx))
    return rasters, (lo[0] - cell / 2, lo[0] + cell * (nx - 0.5),
                     lo[1] - cell / 2, lo[1] + cell * (ny - 0.5))


def nice_length(span_mm: float) -> float:
    """A scale bar's length: 1, 2 or 5 × 10^k mm, about a fifth of ``span_mm``."""
    target = max(span_mm / 5.0, 1e-3)
    k = np.floor(np.log10(target))
    return float(max(m for m in (1, 2, 5) if m * 10 ** k <= target) * 10 ** k)


def cloud_figure(cloud: PointCloud, title: str):
    """The figure (matplotlib ``Figure``, Agg): height panel, and the camera panel when the
    cloud has ``ambient``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    pts = np.asarray(cloud.points, float)
    ok = np.isfinite(pts).all(1)
    pts = pts[ok]
    ambient = cloud.attributes.get("ambient")
    values = [pts[:, 2]] + ([np.asarray(ambient)[ok]] if ambient is not None else [])
    line = cloud.attributes.get("line")
    rasters, extent = top_view(pts, values, None if line is None else np.asarray(line)[ok])
    w, h = extent[1] - extent[0], extent[3] - extent[2]
    scale = PANEL_IN / max(w, h)
    fig = Figure(figsize=(len(rasters) * (w * scale + 1.6) + 0.4, h * scale + 1.4), dpi=150,
                 layout="constrained")
    FigureCanvasAgg(fig)
    fig.suptitle(f"{title} — {len(pts):,} points, top view", fontsize=11)
    lo, hi = np.percentile(pts[:, 2], [0.5, 99.5])
    panels = [("height", "turbo", (lo, hi), "height z, mm")]
    if ambient is not None:         # stretched to the brightest: a 12-bit camera's frames
        top = max(float(np.percentile(values[1], 99.5)), 0.01)   # fill a 16-bit scale to 1/16
        panels.append(("camera (room light, laser off)", "gray", (0.0, top),
                       "grey value, fraction of full scale"))
    for k, (name, cmap, (vmin, vmax), label) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1)
        im = ax.imshow(rasters[k], origin="lower", extent=extent, cmap=cmap, vmin=vmin,
                       vmax=vmax, interpolation="nearest")
        ax.set(title=name, xlabel="x, mm", ylabel="y, mm", aspect="equal")
        ax.set_facecolor("white")
        ax.grid(True, color="0.45", alpha=0.5, linewidth=0.5)
        bar = fig.colorbar(im, ax=ax, shrink=0.9, pad=0.02)
        bar.set_label(label)
        length = nice_length(max(w, h))
        ax.add_artist(AnchoredSizeBar(ax.transData, length, f"{length:g} mm", "lower right",
                                      pad=0.4, color="black", frameon=True, size_vertical=0,
                                      label_top=True))
    return fig


def save_cloud_picture(cloud: PointCloud, path: str | Path, title: str | None = None) -> None:
    """Write :func:`cloud_figure` as a PNG, atomically (``title``: default the file's name)."""
    path = Path(path)
    if not path.parent.is_dir():
        raise FormatError(f"{path}: folder {path.parent} does not exist")
    if len(cloud) == 0:
        raise FormatError(f"{path}: the cloud has no points to draw")
    buf = io.BytesIO()
    cloud_figure(cloud, title or path.stem).savefig(buf, format="png")
    atomic_write_bytes(path, buf.getvalue())
