"""Calibration reports drawn with OpenCV: the field correction's quiver plot of the deviations
before and after correction (Mikkelstrup et al. Fig. 7) with their max / RMS per area (their
Table 1), and the height calibration's residual grid (plate height × line offset).
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from insitu.calibrate.field_areas import AreaStats
from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_bytes

PANEL = 640
MARGIN = 60
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_INK, _GRID, _WHITE = (40, 40, 40), (215, 215, 215), (255, 255, 255)


def _nice(x: float) -> float:
    """The largest 1, 2 or 5 × 10^k not above ``x`` (> 0)."""
    e = 10.0 ** np.floor(np.log10(x))
    return max(m * e for m in (1, 2, 5) if m * e <= x * (1 + 1e-9))


def _panel(points: np.ndarray, dev: np.ndarray, half_mm: float, title: str) -> np.ndarray:
    """One square panel: arrows from each point (N, 2) along its deviation (N, 2), magnified
    so that the RMS one is ~half a grid pitch (the longest at most 1.5), coloured by length,
    with a scale bar."""
    img = np.full((PANEL + 2 * MARGIN, PANEL + 2 * MARGIN, 3), 255, np.uint8)
    px_per_mm = PANEL / (2 * half_mm)

    def to_px(xy: np.ndarray) -> np.ndarray:       # y up in the picture
        return np.column_stack([MARGIN + (xy[:, 0] + half_mm) * px_per_mm,
                                MARGIN + (half_mm - xy[:, 1]) * px_per_mm])

    step = _nice(half_mm / 4)
    for t in np.arange(-np.floor(half_mm / step) * step, half_mm + 1e-9, step):
        a, b = to_px(np.array([[t, -half_mm], [t, half_mm]])), to_px(np.array([[-half_mm, t],
                                                                             [half_mm, t]]))
        for p, q in ((a[0], a[1]), (b[0], b[1])):
            cv2.line(img, tuple(map(int, p)), tuple(map(int, q)), _GRID, 1, cv2.LINE_AA)
        x_lab = to_px(np.array([[t, -half_mm]]))[0]
        cv2.putText(img, f"{t:g}", (int(x_lab[0]) - 12, int(x_lab[1]) + 18), _FONT, 0.4, _INK, 1,
                    cv2.LINE_AA)
    cv2.rectangle(img, (MARGIN, MARGIN), (MARGIN + PANEL, MARGIN + PANEL), _INK, 1)
    length = np.linalg.norm(dev, axis=1) if len(dev) else np.zeros(0)
    longest = float(length.max()) if len(length) and length.max() > 0 else 1e-3
    pitch = 2 * half_mm / max(np.sqrt(len(points)), 2)
    typical = float(np.sqrt(np.mean(length**2))) if len(length) else longest
    mag = _nice(min(pitch / (2 * max(typical, 1e-9)), 1.5 * pitch / longest))
    colours = cv2.applyColorMap(np.clip(length / longest * 255, 0, 255).astype(np.uint8)
                                .reshape(-1, 1), cv2.COLORMAP_TURBO).reshape(-1, 3)
    a, b = to_px(points), to_px(points + dev * mag)
    for p, q, c in zip(a, b, colours):
        p, q = tuple(int(round(v)) for v in p), tuple(int(round(v)) for v in q)
        cv2.circle(img, p, 2, _INK, -1, cv2.LINE_AA)
        cv2.arrowedLine(img, p, q, tuple(int(v) for v in c), 1, cv2.LINE_AA, tipLength=0.25)
    # scale bar: a round length near the longest arrow
    bar_mm = _nice(max(longest, 1e-6))
    x0, y0 = MARGIN, MARGIN + PANEL + 40
    cv2.line(img, (x0, y0), (x0 + int(bar_mm * mag * px_per_mm), y0), _INK, 3)
    cv2.putText(img, f"{bar_mm:g} mm deviation (arrows x{mag:g})", (x0 + int(bar_mm * mag *
                px_per_mm) + 10, y0 + 5), _FONT, 0.5, _INK, 1, cv2.LINE_AA)
    cv2.putText(img, title, (MARGIN, MARGIN - 20), _FONT, 0.55, _INK, 1, cv2.LINE_AA)
    return img


TABLE_HEADER = ("area", "n", "max ux", "uy", "|d|", "RMS ux", "uy", "|d|")


def area_rows(before: Sequence[AreaStats], after: Sequence[AreaStats]) -> list[list[str]]:
    """Table 1 as text cells: per area and state (before / after), n, max [ux, uy, |d|] and
    RMS [ux, uy, |d|], mm (3 decimals)."""
    rows = []
    for label, stats_ in (("before", before), ("after", after)):
        for r in stats_:
            rows.append([f"{label} {r.name}", str(r.n), *(f"{v:.3f}" for v in r.max_mm),
                         *(f"{v:.3f}" for v in r.rms_mm)])
    return rows


def format_area_rows(before: Sequence[AreaStats], after: Sequence[AreaStats]) -> list[str]:
    """:func:`area_rows` as aligned text lines (header first), mm."""
    rows = [list(TABLE_HEADER)] + area_rows(before, after)
    return [f"{r[0]:<26}{r[1]:>5}" + "".join(f"{c:>8}" for c in r[2:]) for r in rows]


def report_image(points: np.ndarray, before: np.ndarray, after: np.ndarray, half_mm: float,
                 before_rows: Sequence[AreaStats], after_rows: Sequence[AreaStats],
                 title: str = "", after_label: str = "after correction") -> np.ndarray:
    """(H, W, 3) BGR image: two quiver panels (before, after) and Table 1 beneath, mm."""
    def rms_max(d):
        n = np.linalg.norm(d, axis=1)
        return f"RMS {np.sqrt(np.mean(n**2)):.3f}, max {n.max():.3f} mm" if len(n) else "no data"

    left = _panel(points, before, half_mm, f"before: {rms_max(before)}")
    right = _panel(points, after, half_mm, f"{after_label}: {rms_max(after)}")
    top = np.hstack([left, right])
    rows = [list(TABLE_HEADER)] + area_rows(before_rows, after_rows)
    lines = textwrap.wrap(title, 110)
    table = np.full((30 + 22 * (len(lines) + len(rows)), top.shape[1], 3), 255, np.uint8)
    y = 25
    for line in lines:
        cv2.putText(table, line, (MARGIN, y), _FONT, 0.5, _INK, 1, cv2.LINE_AA)
        y += 22
    xs = [MARGIN, MARGIN + 330] + [MARGIN + 420 + 95 * k for k in range(6)]
    for r, row in enumerate(rows):
        for x, cell in zip(xs, row):
            cv2.putText(table, cell, (x, y), _FONT, 0.5, _INK, 1, cv2.LINE_AA)
        if r == 0:
            cv2.line(table, (MARGIN, y + 6), (top.shape[1] - MARGIN, y + 6), _GRID, 1)
        y += 22
    return np.vstack([top, table])


def grid_image(heights: np.ndarray, offsets: np.ndarray, rms_mm: np.ndarray, title: str,
               full_scale_mm: float = 0.05) -> np.ndarray:
    """(H, W, 3) BGR image of a residual grid: one cell per plate height (rows, highest on
    top) and line offset (columns), coloured by its RMS (turbo, 0 … ``full_scale_mm``) and
    labelled in µm; empty cells (NaN) grey."""
    cw, ch, left, top = 64, 30, 90, 70
    nh, nx = rms_mm.shape
    img = np.full((top + nh * ch + 40, max(left + nx * cw + 20, 520), 3), 255, np.uint8)
    for k, line in enumerate(textwrap.wrap(title, 90)[:2]):
        cv2.putText(img, line, (10, 22 + 20 * k), _FONT, 0.5, _INK, 1, cv2.LINE_AA)
    level = np.clip(np.nan_to_num(rms_mm, nan=0.0) / full_scale_mm * 255, 0, 255)
    colours = cv2.applyColorMap(level.astype(np.uint8), cv2.COLORMAP_TURBO)
    for r in range(nh):
        i = nh - 1 - r                                        # highest plate on top
        y = top + r * ch
        cv2.putText(img, f"z {heights[i]:+g}", (10, y + 20), _FONT, 0.45, _INK, 1, cv2.LINE_AA)
        for j in range(nx):
            x = left + j * cw
            empty = not np.isfinite(rms_mm[i, j])
            colour = _GRID if empty else tuple(int(c) for c in colours[i, j])
            cv2.rectangle(img, (x, y), (x + cw - 2, y + ch - 2), colour, -1)
            if not empty:
                ink = _WHITE if level[i, j] < 60 or level[i, j] > 200 else _INK
                cv2.putText(img, f"{1000 * rms_mm[i, j]:.0f}", (x + 14, y + 20), _FONT, 0.45,
                            ink, 1, cv2.LINE_AA)
    for j in range(nx):
        cv2.putText(img, f"x {offsets[j]:+g}", (left + j * cw + 4, top + nh * ch + 18), _FONT,
                    0.4, _INK, 1, cv2.LINE_AA)
    return img


def bars_image(values: Sequence[float], title: str, unit: str = "px") -> np.ndarray:
    """(H, W, 3) BGR bar chart of ``values`` (one bar per view, numbered from 1) with the
    median as a line: which views fit worse than the others."""
    v = np.asarray(values, float)
    bw, left, top, height = 28, 70, 60, 220
    img = np.full((top + height + 50, max(left + len(v) * bw + 30, 520), 3), 255, np.uint8)
    for k, line in enumerate(textwrap.wrap(title, 90)[:2]):
        cv2.putText(img, line, (10, 22 + 20 * k), _FONT, 0.5, _INK, 1, cv2.LINE_AA)
    full = _nice(max(float(np.nanmax(v)) if len(v) else 1.0, 1e-6)) * 2

    def y(value: float) -> int:
        return int(top + height - height * min(value / full, 1.0))

    for t in np.linspace(0, full, 5):
        cv2.line(img, (left, y(t)), (img.shape[1] - 20, y(t)), _GRID, 1)
        cv2.putText(img, f"{t:.3g}", (10, y(t) + 5), _FONT, 0.4, _INK, 1, cv2.LINE_AA)
    for i, value in enumerate(v):
        x = left + i * bw
        cv2.rectangle(img, (x + 3, y(value)), (x + bw - 3, y(0)), (200, 140, 60), -1)
        cv2.putText(img, str(i + 1), (x + 6, top + height + 18), _FONT, 0.4, _INK, 1,
                    cv2.LINE_AA)
    if len(v):
        m = float(np.median(v))
        cv2.line(img, (left, y(m)), (img.shape[1] - 20, y(m)), (60, 60, 220), 1)
        cv2.putText(img, f"median {m:.3g} {unit}", (left, top + height + 40), _FONT, 0.45,
                    (60, 60, 220), 1, cv2.LINE_AA)
    return img


def write_report_png(path: str | Path, image: np.ndarray) -> None:
    """Encode as PNG and write atomically."""
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise FormatError(f"{path}: OpenCV could not encode the report as PNG")
    atomic_write_bytes(path, buf.tobytes())
