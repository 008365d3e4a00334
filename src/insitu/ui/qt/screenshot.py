"""Render the application on a recorded scan with a placed pattern and save pictures (the
README's docs/gui*.png, the OpenGL tests, the benchmark). Needs a display with OpenGL 3.3 (on
a headless machine: ``QT_QPA_PLATFORM=xcb xvfb-run -a python -m insitu.ui.qt.screenshot``).
``scripts/gui-pictures.sh`` makes the README's pictures (the step block recorded at binning 2,
a QR code placed on its 10 mm step; the top view with camera colours, and the iso view).

``--view-png V.png`` also saves the 3-D view's own framebuffer and ``V.json`` beside it: the
camera (centre, distance, angles, field of view, orthographic), the image size, the colour
scale's z range, the cloud's shade (dimmed under pens' paths), the colour bar's range, the
grid step, the GL renderer, the cloud's points and the projected pattern's points (N, 3) mm
— what a test needs to check the picture.
``--extra VIEW:COLOURS:PATH`` saves more pictures of the same window (COLOURS: height or
camera), the k-th one's view as ``V-k.png`` and ``V-k.json`` too. ``--docks DIR`` saves
each dock as the operator sees it then, raised in turn, as ``DIR/gui-dock-NAME.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from PySide6.QtCore import QEventLoop, QSettings
from PySide6.QtGui import QImage, QPainter, QSurfaceFormat
from PySide6.QtWidgets import QApplication

from insitu.formats.project import RigChoice
from insitu.ui.qt.app import surface_format
from insitu.ui.qt.forms import stylesheet
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.view_overlay import colour_bar_range


def wait_until(app: QApplication, condition, timeout_s: float = 30.0, what: str = "") -> None:
    """Process events until ``condition()``; RuntimeError after ``timeout_s``."""
    t0 = time.perf_counter()
    while not condition():
        if time.perf_counter() - t0 > timeout_s:
            raise RuntimeError(f"timed out after {timeout_s:g} s waiting for {what}")
        app.processEvents(QEventLoop.AllEvents, 20)
        time.sleep(0.005)


def build(app: QApplication, replay: Path, height_cal: Path | None, pattern: str | None,
          at: tuple[float, float], width: float, settings_file: Path, binning: int = 4) -> MainWindow:
    """The window connected to the simulated rig (image size of the recording), the scan
    replayed and the pattern placed and checked."""
    window = MainWindow(QSettings(str(settings_file), QSettings.IniFormat))
    window.resize(1280, 800)
    window.show()
    window.connect_rig(RigChoice(binning=binning))
    wait_until(app, lambda: window.station is not None, 120, "the rig")
    if height_cal is not None:
        window.load_height_cal(height_cal)
        wait_until(app, lambda: window.session.height_cal is not None, 60, "the height cal")
    ui = window.scan_panel.ui
    ui.sourceCombo.setCurrentIndex(1)
    ui.replayEdit.setText(str(replay))
    window.scan_panel.start()
    wait_until(app, lambda: window.session.cloud is not None, 120, "the scan")
    s = window.session
    if pattern:
        window.place_panel.add_pattern(pattern)
        s.update_selected(at_mm=at, width_mm=width)
        wait_until(app, lambda: len(s.plans) == 1 and not window._plan_timer.isActive()
                   and not window.runner.running("plan"), 60, "the plan")
        if s.plans[0].error:
            raise RuntimeError(s.plans[0].error)
        window.docks["place"].raise_()
    return window


def show(app: QApplication, window: MainWindow, view_name: str, camera_colours: bool) -> None:
    """Set the view, framed on the cloud and the patterns, and the colouring; draw it."""
    window.view.set_view(view_name)
    window.binding.frame_all()
    window.view_menu.camera_colours.setChecked(camera_colours)
    wait_until(app, lambda: bool(window.view.renderer_name), 10, "OpenGL")
    app.processEvents()


def grab(window: MainWindow) -> QImage:
    """The window as the screen shows it: the 3-D view's framebuffer (with its overlay)
    painted where the view is."""
    img = window.grab().toImage()
    view = window.view
    p = QPainter(img)
    p.drawImage(view.mapTo(window, view.rect().topLeft()),
                view.grabFramebuffer().scaled(view.size()))
    p.end()
    return img


def save_docks(app: QApplication, window: MainWindow, folder: Path) -> list[Path]:
    """Each dock raised in turn and saved as ``folder/gui-dock-NAME.png``."""
    out = []
    for name, dock in window.docks.items():
        dock.show()
        dock.raise_()
        for _ in range(10):
            app.processEvents(QEventLoop.AllEvents, 20)
        out.append(folder / f"gui-dock-{name}.png")
        dock.grab().save(str(out[-1]))
    return out


def view_info(window: MainWindow) -> dict:
    view, s = window.view, window.session
    cam = view.camera
    plan = s.plans[0].plan if s.plans else None
    bar = colour_bar_range(view)
    at = view.mapTo(window, view.rect().topLeft())
    return {"width": view.width(), "height": view.height(), "in_window": [at.x(), at.y()],
            "device_pixel_ratio": view.devicePixelRatioF(),
            "centre": list(map(float, cam.centre)), "distance_mm": cam.distance_mm,
            "azimuth_deg": cam.azimuth_deg, "elevation_deg": cam.elevation_deg,
            "fov_deg": cam.fov_deg, "ortho": cam.ortho, "z_range": list(view.renderer.z_range),
            "shade": view.renderer.shade,
            "colour_bar": None if bar is None else [bar[0], bar[1], bar[2]],
            "grid_step_mm": None if view.grid is None else view.grid.step_mm,
            "renderer": view.renderer_name,
            "camera_colours": bool(view.renderer.camera_colours and view.has_camera_colours),
            "cloud_points": s.cloud.points.tolist(),
            "pattern_points": plan.projection.points.tolist() if plan else [],
            "outline_corners": [] if view.handles is None else view.handles.corners.tolist(),
            "handle_z": view.handle_z}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path, help="PNG of the whole window")
    ap.add_argument("--replay", type=Path, required=True)
    ap.add_argument("--height-cal", type=Path)
    ap.add_argument("--binning", type=int, default=4, help="of the recording")
    ap.add_argument("--pattern")
    ap.add_argument("--at", type=float, nargs=2, default=(0.0, 0.0))
    ap.add_argument("--width", type=float, default=10.0)
    ap.add_argument("--view", default="top", choices=["top", "front", "side", "iso"])
    ap.add_argument("--camera-colours", action="store_true")
    ap.add_argument("--extra", action="append", default=[], metavar="VIEW:COLOURS:PATH")
    ap.add_argument("--view-png", type=Path)
    ap.add_argument("--docks", type=Path, metavar="DIR", help="a picture of every dock")
    args = ap.parse_args(argv)
    QSurfaceFormat.setDefaultFormat(surface_format())
    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setStyleSheet(stylesheet())
    settings = args.out.with_suffix(".settings.ini")
    window = build(app, args.replay, args.height_cal, args.pattern, tuple(args.at), args.width,
                   settings, args.binning)
    settings.unlink(missing_ok=True)
    show(app, window, args.view, args.camera_colours)
    shots = [(args.view, args.camera_colours, args.out)] + \
        [(v, c == "camera", Path(p)) for v, c, p in (e.split(":", 2) for e in args.extra)]
    for k, (view_name, camera_colours, path) in enumerate(shots):
        show(app, window, view_name, camera_colours)
        grab(window).save(str(path))
        if args.view_png is not None:
            v = args.view_png if k == 0 else \
                args.view_png.with_name(f"{args.view_png.stem}-{k}{args.view_png.suffix}")
            window.view.grabFramebuffer().save(str(v))
            v.with_suffix(".json").write_text(json.dumps(view_info(window)))
    if args.docks is not None:
        save_docks(app, window, args.docks)
    window.saved.mark_clean()        # a scripted session: nothing to save
    window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
