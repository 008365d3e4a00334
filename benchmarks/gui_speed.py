"""Speed of the GUI: frame time of the 3-D view for 1 and 5 million points (target < 50 ms
with Mesa's software renderer for 1 M) while the view moves (thinned cloud) and at rest (every
point), and the time from pressing Scan to the first points in the view for a 200-line live
scan of the simulated step block (target < 1 s).

The clouds are in scan order (line after line), as every measured cloud is; a software
renderer is several times slower on points in random order.

Needs a display with OpenGL 3.3; on a headless machine:
    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1280x1024x24" \
        .venv/bin/python benchmarks/gui_speed.py
"""

from __future__ import annotations

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


def frame_ms(app, window, points: np.ndarray, moving: bool, frames: int = 20
             ) -> tuple[float, float]:
    """(median wall ms per orbiting frame, first frame incl. upload ms), GPU finished."""
    view = window.view
    view.set_cloud(points)
    view.frame_all(points.min(0), points.max(0))
    times = []
    for i in range(frames + 1):
        view.moving = moving
        view.camera.orbit(3.0, 0.0)
        t0 = time.perf_counter()
        view.repaint()
        view.makeCurrent()
        GL.glFinish()
        view.doneCurrent()
        app.processEvents()
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times[1:])), times[0]


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
    QSurfaceFormat.setDefaultFormat(surface_format())
    app = QApplication.instance() or QApplication(sys.argv[:1])
    with tempfile.TemporaryDirectory() as tmp:
        window = MainWindow(QSettings(str(Path(tmp) / "s.ini"), QSettings.IniFormat))
        window.resize(1280, 800)
        window.show()
        wait_until(app, lambda: bool(window.view.renderer_name), 20, "OpenGL")
        table = Table(title=f"GUI speed ({window.view.renderer_name}, view "
                            f"{window.view.width()}×{window.view.height()} px)")
        table.add_column("measure")
        table.add_column("value", justify="right")
        table.add_column("target", justify="right")
        for n in (1_000_000, 5_000_000):
            cloud = surface_cloud(n)
            for moving in (True, False):
                med, first = frame_ms(app, window, cloud, moving)
                state = "moving (thinned)" if moving else "at rest (all points)"
                table.add_row(f"frame, {n / 1e6:g} M points, {state}", f"{med:.1f} ms",
                              "< 50 ms" if n == 1_000_000 and moving else "")
            table.add_row(f"first frame with upload, {n / 1e6:g} M points", f"{first:.0f} ms", "")
        window.session.set_cloud(None)
        for binning in (1, 2):
            first, total, lines = first_points_s(app, window, binning)
            size = f"{2448 // binning}×{2048 // binning}"
            table.add_row(f"scan {lines} lines at {size} px: first points", f"{first:.2f} s",
                          "< 1 s")
            table.add_row(f"scan {lines} lines at {size} px: whole scan", f"{total:.1f} s", "")
        window.saved.mark_clean()        # a scripted session: nothing to save
        window.close()
    Console().print(table)


if __name__ == "__main__":
    main()
