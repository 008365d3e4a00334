"""Speed of the GUI: frame time of the 3-D view for 1 and 5 million points, coloured by
height and by the camera's ambient gray (targets for 1 M on Mesa's software renderer: ≤ 50 ms
while the view moves, ≤ 100 ms at rest, camera colours on), and the time from pressing Scan
to the first points in the view for a 200-line live scan of the simulated step block
(target < 1 s). Also: a toggle of the colours uploads nothing.

The clouds are in scan order (line after line), as every measured cloud is; a software
renderer is several times slower on points in random order. ``--sizes 1`` and ``--no-scan``
make a short run.

Needs a display with OpenGL 3.3; on a headless machine:
    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1280x1024x24" \
        .venv/bin/python benchmarks/gui_speed.py
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from OpenGL import GL
from PySide6.QtCore import QSettings
from PySide6.QtGui import QSurfaceFormat
from PySide6.QtWidgets import QApplication
from rich.console import Console
from rich.table import Table

from insitu.formats.project import RigChoice
from insitu.ui.qt.app import surface_format
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.screenshot import wait_until


def surface_cloud(n: int, lines: int = 1000) -> np.ndarray:
    """(n, 3) points on a wavy 200 × 200 mm surface, mm, as ``lines`` scan lines along y."""
    per = n // lines
    x = np.repeat(np.linspace(-100, 100, lines), per)
    y = np.tile(np.linspace(-100, 100, per), lines)
    z = 10 * np.sin(x / 15) * np.cos(y / 20)
    return np.c_[x, y, z]


def ambient_gray(points: np.ndarray) -> np.ndarray:
    """(n,) float32 0…1: a camera-like gray (a texture of stripes and blobs) per point."""
    x, y = points[:, 0], points[:, 1]
    return (0.5 + 0.3 * np.sin(x / 3) * np.cos(y / 7) + 0.1 * np.sin(x * y / 50)
            ).astype(np.float32)


def frame_ms(app, window, points: np.ndarray, moving: bool, camera: bool = False,
             frames: int = 20) -> tuple[float, float, int, float]:
    """(median wall ms per orbiting frame, first frame incl. upload ms, points drawn, median
    CPU ms per frame of this process — llvmpipe's threads included: on a machine shared with
    other work the wall time waits for the CPU, the CPU time does not), GPU finished;
    ``camera``: the cloud carries its ambient gray and is coloured by it."""
    view = window.view
    view.set_cloud(points, ambient=ambient_gray(points) if camera else None)
    view.set_camera_colours(camera)
    view.set_view("iso")
    view.frame_all(points.min(0), points.max(0))
    times, cpu = [], []
    for _ in range(frames + 1):
        view.moving = moving
        view.camera.orbit(3.0, 0.0)
        t0, c0 = time.perf_counter(), time.process_time()
        view.repaint()
        view.makeCurrent()
        GL.glFinish()
        view.doneCurrent()
        app.processEvents()
        times.append((time.perf_counter() - t0) * 1e3)
        cpu.append((time.process_time() - c0) * 1e3)
    return (float(np.median(times[1:])), times[0], view.renderer.points.drawn,
            float(np.median(cpu[1:])))


def toggle_uploads(app, window) -> int:
    """Buffer uploads caused by toggling the colours twice (0: the toggle is a uniform)."""
    pts = window.view.renderer.points
    before = pts.positions.uploads + pts.ambient.uploads
    for on in (False, True):
        window.view.set_camera_colours(on)
        window.view.repaint()
        app.processEvents()
    return pts.positions.uploads + pts.ambient.uploads - before


def first_points_s(app, window, binning: int) -> tuple[float, float, int]:
    """(s to the first points in the view, s for the whole scan, lines) of a 200-line scan."""
    window.connect_rig(RigChoice(binning=binning))
    wait_until(app, lambda: window.station is not None and
               window.session.rig_choice.binning == binning and
               not window.runner.running("connect"), 120, "the rig")
    ui = window.scan_panel.ui
    ui.sourceCombo.setCurrentIndex(0)
    window.scan_panel.set_region((-14.0, 14.0, -46.0, 46.0))
    ui.spacingSpin.setValue(28.0 / 199)
    seen: list[float] = []
    window.session.live_points_added.connect(lambda _p: seen.append(time.perf_counter()))
    t0 = time.perf_counter()
    window.scan_panel.start()
    wait_until(app, lambda: bool(seen) and window.view.renderer.points.count > 0, 60,
               "the first points")
    first = seen[0] - t0
    wait_until(app, lambda: not window.runner.running("scan"), 600, "the scan")
    return first, time.perf_counter() - t0, ui.progressBar.maximum()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[1, 5], help="million points")
    ap.add_argument("--no-scan", action="store_true", help="leave out the live scans")
    args = ap.parse_args()
    QSurfaceFormat.setDefaultFormat(surface_format())
    app = QApplication.instance() or QApplication(sys.argv[:1])
    with tempfile.TemporaryDirectory() as tmp:
        window = MainWindow(QSettings(str(Path(tmp) / "s.ini"), QSettings.IniFormat))
        window.resize(1280, 800)
        window.show()
        wait_until(app, lambda: bool(window.view.renderer_name), 20, "OpenGL")
        table = Table(title=f"GUI speed ({window.view.renderer_name}, view "
                            f"{window.view.width()}×{window.view.height()} px, load average "
                            f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
        table.add_column("measure")
        table.add_column("value", justify="right")
        table.add_column("target", justify="right")
        table.add_column("points drawn", justify="right")
        table.add_column("CPU (2 cores)", justify="right")
        for n in (int(m * 1e6) for m in args.sizes):
            cloud = surface_cloud(n)
            for camera in (False, True):
                colours = "camera colours" if camera else "height colours"
                for moving in (True, False):
                    med, first, drawn, cpu = frame_ms(app, window, cloud, moving, camera)
                    state = "moving" if moving else "at rest"
                    target = ("≤ 50 ms" if moving else "≤ 100 ms") if n == 1_000_000 else ""
                    table.add_row(f"frame, {n / 1e6:g} M points, {colours}, {state}",
                                  f"{med:.1f} ms", target, f"{drawn:,}", f"{cpu:.0f} ms")
                table.add_row(f"first frame with upload, {n / 1e6:g} M points, {colours}",
                              f"{first:.0f} ms", "", "", "")
            table.add_row("uploads when the colours are toggled twice",
                          str(toggle_uploads(app, window)), "0", "", "")
        window.session.set_cloud(None)
        for binning in () if args.no_scan else (1, 2):
            first, total, lines = first_points_s(app, window, binning)
            size = f"{2448 // binning}×{2048 // binning}"
            table.add_row(f"scan {lines} lines at {size} px: first points", f"{first:.2f} s",
                          "< 1 s", "", "")
            table.add_row(f"scan {lines} lines at {size} px: whole scan", f"{total:.1f} s", "",
                          "", "")
        window.saved.mark_clean()        # a scripted session: nothing to save
        window.close()
    Console().print(table)


if __name__ == "__main__":
    main()
