"""``insitu gui``: start the Qt application (OpenGL 3.3 core profile for the 3-D view)."""

from __future__ import annotations

import sys
from pathlib import Path

from PySide6.QtGui import QSurfaceFormat
from PySide6.QtWidgets import QApplication

from insitu.formats.project import SIM_BINNING, RigChoice
from insitu.ui.qt.forms import stylesheet
from insitu.ui.qt.main_window import MainWindow


def surface_format() -> QSurfaceFormat:
    """OpenGL 3.3 core with a depth buffer, no multisampling (it costs a software renderer
    half its speed on point clouds); set before the application starts."""
    fmt = QSurfaceFormat()
    fmt.setVersion(3, 3)
    fmt.setProfile(QSurfaceFormat.CoreProfile)
    fmt.setDepthBufferSize(24)
    return fmt


def run(project: Path | None = None, rig: Path | None = None, workpiece: str = "step-block",
        binning: int = SIM_BINNING) -> int:
    """Open the main window and connect the rig (the simulated one unless ``rig`` names a rig
    file) — with the last job marked opened when it did not finish (Resume finishes it) —,
    or open ``project`` without connecting its rig (the operator connects it: Rig ▸
    Connect); returns the exit code."""
    QSurfaceFormat.setDefaultFormat(surface_format())
    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName("insitu")
    app.setStyleSheet(stylesheet())
    window = MainWindow()
    window.show()
    if project is not None:
        window.open_project(project)
    else:
        window.connect_rig(RigChoice(workpiece=workpiece, binning=binning, rig_file=rig))
        window.restore_unfinished()
    return app.exec()
