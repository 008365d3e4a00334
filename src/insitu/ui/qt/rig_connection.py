"""The main window's rig: connecting it off the GUI thread ("connecting…" while it does),
disconnecting, the calibrations in use (the height calibration loaded or fitted, the field
correction applied to the station) and the status bar's lines about them."""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from PySide6.QtWidgets import QFileDialog

from insitu.formats.project import RigChoice
from insitu.services import load_height_calibration
from insitu.ui.model import operations as ops


def age_text(created: str | None) -> str:
    """"2 h old" from an ISO-8601 UTC time."""
    try:
        t = datetime.fromisoformat(created.replace("Z", "+00:00"))
    except (AttributeError, ValueError):
        return "age unknown"
    s = (datetime.now(timezone.utc) - t).total_seconds()
    for unit, n in (("d", 86400), ("h", 3600), ("min", 60)):
        if s >= n:
            return f"{s / n:.0f} {unit} old"
    return "new"


class RigConnection:
    """A mixin of :class:`~insitu.ui.qt.main_window.MainWindow`: ``station`` (None: not
    connected), ``connecting`` (a connection under way)."""

    def _rig_named(self) -> None:
        """Rig ▸ Connect names the rig it connects: the session's (a project's) choice."""
        rig_file = self.session.rig_choice.rig_file
        self.connect_action.setText("&Connect simulated rig" if rig_file is None
                                    else f"&Connect rig {Path(rig_file).name}")

    def _rig_state(self, camera: str, head: str) -> None:
        self.camera_label.setText(camera)
        self.head_label.setText(head)
        self.connect_action.setEnabled(not self.connecting)
        self.session.rig_changed.emit()
        self._plan_timer.start()

    def disconnect_rig(self) -> None:
        """Close the station (laser off, devices released); the status says so."""
        self._rig_epoch += 1
        self.connecting = False
        if self.station is not None:
            self.station.close()
            self.station = None
        self.clear_message("rig")
        self._rig_state("camera: not connected", "scan head: not connected")

    def connect_rig(self, choice: RigChoice | None = None) -> None:
        """Connect the station of ``choice`` (default: the session's), off the GUI thread;
        "connecting…" until it answers. Only the operator's action (or ``insitu gui``
        without a project) calls this: opening a project never connects its rig, so a rig
        file that came with it runs nothing."""
        choice = choice or self.session.rig_choice
        field, epoch = self.session.field_path, self._rig_epoch
        task = self.runner.start("connect", lambda p, c, f: (epoch, choice,
                                                             ops.connect(choice, field)),
                                 self._connected, self._not_connected)
        if task is None:
            return
        self.connecting = True
        name = ("the simulated rig" if choice.rig_file is None
                else f"rig {Path(choice.rig_file).name}")
        self.show_message(f"connecting {name}…", "rig")
        self._rig_state("camera: connecting…", "scan head: connecting…")

    def _not_connected(self, message: str, _cancelled: bool) -> None:
        self.connecting = False
        self._rig_state("camera: not connected", "scan head: not connected")
        self.show_error(message, "rig")

    def _connected(self, result) -> None:
        epoch, choice, station = result
        self.connecting = False
        if epoch != self._rig_epoch:    # a project was opened meanwhile: not its rig
            station.close()
            self.connect_action.setEnabled(True)
            return
        if self.station is not None:
            self.station.close()
        self.station = station
        self.session.rig_choice = choice
        self._rig_named()
        nominal = station.rig.head
        self.binding.show_field(nominal.field_size_mm, nominal.z_range_mm)
        if self.session.cloud is None:            # the whole scan field
            hx, hy = np.asarray(nominal.field_size_mm, float) / 2
            self.view.frame_all((-hx, -hy, min(nominal.z_range_mm)),
                                (hx, hy, max(nominal.z_range_mm)))
        self._rig_state(*station.describe())
        self.show_message("rig connected", "rig")

    def _rig_file_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Rig file", "", "Rig files (*.json)")
        if path:
            self.connect_rig(replace(self.session.rig_choice, rig_file=Path(path)))

    # -- calibrations ----------------------------------------------------------------------
    def load_height_cal(self, path: Path | None) -> None:
        """Use the height calibration file (or recorded folder, fitted now) ``path``."""
        if path is None:
            self.session.height_cal_path = self.session.height_cal = None
            self.calib_label.setText("no height calibration")
            self.update_title()
            return
        self.runner.start("height-cal", lambda p, c, f: (path, load_height_calibration(path, p)),
                          self._height_cal_loaded, lambda m, _c: self.show_error(m, "height"))

    def _height_cal_loaded(self, result) -> None:
        path, cal = result
        self.session.height_cal_path, self.session.height_cal = path, cal
        self.scan_panel.ui.heightCalEdit.setText(str(path))
        self.calib_label.setText(f"height calibration {age_text(cal.created)}")
        self.clear_message("height")
        self.update_title()

    def calibration_done(self, kind: str, path: Path) -> None:
        if kind == "height":
            self.load_height_cal(path)
        elif kind == "field":
            self.session.field_path = path
            if self.station is not None:
                self.station.use_field(path)
                self._plan_timer.start()
        else:
            self.session.camera_cal_path = path
        self.update_title()
