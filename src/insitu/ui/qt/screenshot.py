"""Render the application on a recorded scan with a placed pattern and save pictures (the
README's docs/gui.png, the OpenGL test, the benchmark). Needs a display with OpenGL 3.3 (on a
headless machine: ``QT_QPA_PLATFORM=xcb xvfb-run -a python -m insitu.ui.qt.screenshot``).
docs/gui.png is the step block recorded at binning 2 with the logo across a step edge::

    insitu sim record scan --binning 2 -o rec2
    insitu sim record height-calibration --binning 2 -o hcal2
    insitu calibrate height hcal2 -o h2.json
    python -m insitu.ui.qt.screenshot docs/gui.png --replay rec2 --height-cal h2.json \\
        --pattern patterns/logo.svg --at 0 0 --width 18

``--view-png V.png`` also saves the 3-D view's own framebuffer and ``V.json`` beside it: the
camera (centre, distance, angles, field of view), the image size, the colour scale's z range,
the GL renderer, the cloud's points and the projected pattern's points (N, 3) mm — what a
test needs to check the picture.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from PySide6.QtCore import QEventLoop, QSettings
from PySide6.QtGui import QSurfaceFormat
from PySide6.QtWidgets import QApplication

from insitu.formats.project import RigChoice
from insitu.ui.qt.app import surface_format
from insitu.ui.qt.forms import stylesheet
from insitu.ui.qt.main_window import MainWindow


def wait_until(app: QApplication, condition, timeout_s: float = 30.0, what: str = "") -> None:
    """Process events until ``condition()``; RuntimeError after ``timeout_s``."""
    t0 = time.perf_counter()
    while not condition():
        if time.perf_counter() - t0 > timeout_s:
            raise RuntimeError(f"timed out after {timeout_s:g} s waiting for {what}")
        app.processEvents(QEventLoop.AllEvents, 20)
        time.sleep(0.005)


def build(app: QApplication, replay: Path, height_cal: Path | None, pattern: str | None,
          at: tuple[float, float], width: float, settings_file: Path) -> MainWindow:
    """The window connected to the simulated rig (image size of the recording), the scan
    replayed and the pattern placed and checked."""
    window = MainWindow(QSettings(str(settings_file), QSettings.IniFormat))
    window.resize(1280, 800)
    window.show()
    window.connect_rig(RigChoice(binning=4))
    wait_until(app, lambda: window.station is not None, what="the rig")
    if height_cal is not None:
        window.load_height_cal(height_cal)
        wait_until(app, lambda: window.session.height_cal is not None, 60, "the height cal")
    ui = window.scan_panel.ui
    ui.sourceCombo.setCurrentIndex(1)
    ui.replayEdit.setText(str(replay))
    window.scan_panel.start()
    wait_until(app, lambda: window.session.cloud is not None, 60, "the scan")
    if pattern:
        window.place_panel.add_pattern(pattern)
        window.session.update_selected(at_mm=at, width_mm=width)
        wait_until(app, lambda: len(window.session.plans) == 1, 30, "the plan")
        if window.session.plans[0].error:
            raise RuntimeError(window.session.plans[0].error)
        window.docks["place"].raise_()
    return window


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path, help="PNG of the whole window")
    ap.add_argument("--replay", type=Path, required=True)
    ap.add_argument("--height-cal", type=Path)
    ap.add_argument("--pattern")
    ap.add_argument("--at", type=float, nargs=2, default=(0.0, 0.0))
    ap.add_argument("--width", type=float, default=10.0)
    ap.add_argument("--view", default="iso", choices=["top", "front", "side", "iso"])
    ap.add_argument("--view-png", type=Path)
    args = ap.parse_args(argv)
    QSurfaceFormat.setDefaultFormat(surface_format())
    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setStyleSheet(stylesheet())
    window = build(app, args.replay, args.height_cal, args.pattern, tuple(args.at), args.width,
                   args.out.with_suffix(".settings.ini"))
    args.out.with_suffix(".settings.ini").unlink(missing_ok=True)
    view = window.view
    view.set_view(args.view)
    wait_until(app, lambda: bool(view.renderer_name), 10, "OpenGL")
    app.processEvents()
    window.grab().save(str(args.out))
    if args.view_png is not None:
        view.grabFramebuffer().save(str(args.view_png))
        cam, s = view.camera, window.session
        plan = s.plans[0].plan if s.plans else None
        info = {"width": view.width(), "height": view.height(),
                "device_pixel_ratio": view.devicePixelRatioF(),
                "centre": list(map(float, cam.centre)), "distance_mm": cam.distance_mm,
                "azimuth_deg": cam.azimuth_deg, "elevation_deg": cam.elevation_deg,
                "fov_deg": cam.fov_deg, "z_range": list(view.renderer.z_range),
                "renderer": view.renderer_name,
                "cloud_points": s.cloud.points.tolist(),
                "pattern_points": plan.projection.points.tolist() if plan else []}
        args.view_png.with_suffix(".json").write_text(json.dumps(info))
    window.saved.mark_clean()        # a scripted session: nothing to save
    window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
