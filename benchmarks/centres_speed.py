"""Speed of the line-centre methods on full-size (2448 × 2048, uint8) frames, one core.

Frames: the simulated camera's line frames (speckle, ambient light, shot and read noise,
saturation, secondary reflections) on the step block and the freeform part. Prints a table:
method, frames/s, MPix/s, ms/frame (median over all frames and rounds). Target: the gray
centroid and Steger ≥ 100 frames/s. "plain" rows are a gray centroid without the shared
detection stage (the column's maximum, a fixed threshold), for comparison. line_direction (a
top-hat's structure tensor) should take a few ms; the colour row includes making the BGR
frame. "the scan's band" is what a scan runs: the band the light plane allows over the focus
range (reconstruct.plane.band_and_side). The photograph row: the frame as a colour JPEG shrunk
to 1920 × 1080 (insitu centres' photo_centres).
Run: .venv/bin/python benchmarks/centres_speed.py
"""

from __future__ import annotations

import os
import time

os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core, honestly

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from insitu.reconstruct.plane import band_and_side  # noqa: E402
from insitu.sim.rig import NOMINAL_HEAD, default_rig  # noqa: E402
from insitu.sim.workpieces import make_workpiece  # noqa: E402
from insitu.sim.world import SimWorld  # noqa: E402
from insitu.vision.centres import gray_centroid, line_centres, line_direction, photo_centres  # noqa: E402
from insitu.vision.extract import extract_centres  # noqa: E402
from insitu.vision.steger import gaussian_peak, steger  # noqa: E402

cv2.setNumThreads(1)


def before_gray_centroid(image, k=0.5, min_peak=40.0, window=12, median=3):
    """A plain gray centroid: the column's maximum, a threshold k × peak, no shared detection
    stage (a baseline for the table)."""
    img = cv2.medianBlur(image, median) if median and median > 1 else image
    H, W = img.shape
    row = np.argmax(img, axis=0)
    cols = np.arange(W)
    gmax = img[row, cols].astype(np.float64)
    keep = gmax >= min_peak
    if window is None:
        band = img[:, keep].astype(np.float64)
        rows = np.arange(H, dtype=np.float64)[:, None]
        background = np.median(band, axis=0)
    else:
        offs = np.arange(-window, window + 1)[:, None]
        rows_i = np.clip(row[keep][None, :] + offs, 0, H - 1)
        band = img[rows_i, cols[keep][None, :]].astype(np.float64)
        rows = rows_i.astype(np.float64)
        background = np.minimum(band[0], band[-1])
    K = k * gmax[keep]
    g = np.where(band > K, band, 0.0)
    total = g.sum(axis=0)
    v = (g * rows).sum(axis=0) / np.where(total > 0, total, 1.0)
    width = (g > 0).sum(axis=0).astype(np.float64)
    return cols[keep], v, gmax[keep], width, gmax[keep] - background


RIG = default_rig(seed=0)


def frames(n_per_part: int = 3) -> list[np.ndarray]:
    out = []
    for name in ("step-block", "freeform"):
        r = SimWorld(RIG, parts=[make_workpiece(name)]).renderer()
        for x in np.linspace(-8, 8, n_per_part):
            out.append(r.line_frame([x, -45], [x, 45]))
    return out


def scan_band(x: float = 0.0):
    """The band and side a scan searches the line of x = const in (the operator's camera)."""
    lo, hi, upper = band_and_side(RIG.operator.camera, [x, -45], [x, 45],
                                  NOMINAL_HEAD.pivot_height_mm, NOMINAL_HEAD.z_range_mm)
    return (lo, hi), upper


def photograph(f: np.ndarray) -> np.ndarray:
    """A frame as a colour JPEG photograph, 1920 × 1080 (red laser, warm room)."""
    small = cv2.resize(f, (1920, 1080), interpolation=cv2.INTER_AREA).astype(np.float32)
    bgr = cv2.merge([0.5 * small, 0.6 * small, np.minimum(1.4 * small, 255)])
    ok, jpg = cv2.imencode(".jpg", bgr.astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 90])
    return cv2.imdecode(jpg, cv2.IMREAD_COLOR)


BAND, UPPER = scan_band()


METHODS = {
    "gray_centroid (default, ±12 rows)": gray_centroid,
    "gray_centroid, background=True": lambda f: gray_centroid(f, background=True),
    "gray_centroid, continuity=False": lambda f: gray_centroid(f, continuity=False),
    "gray_centroid, window=None": lambda f: gray_centroid(f, window=None),
    "plain gray_centroid": before_gray_centroid,
    "plain gray_centroid, window=None": lambda f: before_gray_centroid(f, window=None),
    "gaussian_peak": gaussian_peak,
    "steger": steger,
    "line_centres(gray, auto direction)": line_centres,
    "line_centres(steger, auto direction)": lambda f: line_centres(f, "steger"),
    "line_direction": lambda f: [line_direction(f)],
    "extract_centres (ours: steger + along-line window)": extract_centres,
    "extract_centres, the scan's band (what a scan runs)":
        lambda f: extract_centres(f, band=BAND, upper=UPPER),
    "photo_centres(steger), 1920 × 1080 colour photograph": ("photo", photo_centres),
    "line_centres(steger, BGR colour, auto channel)":
        lambda f: line_centres(cv2.merge([f // 2, f, f // 3]), "steger"),
}


def main(rounds: int = 10) -> None:
    imgs = frames()
    photos = [photograph(f) for f in imgs]
    H, W = imgs[0].shape
    table = Table(title=f"line centres, {W} × {H} uint8, one core, {len(imgs)} frames")
    for col in ("method", "frames/s", "MPix/s", "ms/frame", "points/frame"):
        table.add_column(col, justify="left" if col == "method" else "right")
    for name, fn in METHODS.items():
        times, points = [], []
        n = rounds if "None" not in name else max(2, rounds // 4)
        photo = isinstance(fn, tuple)
        fn = fn[1] if photo else fn
        for _ in range(n):
            for img in (photos if photo else imgs):
                t = time.perf_counter()
                res = fn(img)
                times.append(time.perf_counter() - t)
                points.append(len(res[0]) if isinstance(res, tuple) else len(res))
        dt = float(np.median(times))
        px = 1920 * 1080 if photo else H * W
        table.add_row(name, f"{1 / dt:.0f}", f"{px / dt / 1e6:.0f}", f"{dt * 1e3:.2f}",
                      f"{np.mean(points):.0f}")
    Console(width=120).print(table)


if __name__ == "__main__":
    main()
