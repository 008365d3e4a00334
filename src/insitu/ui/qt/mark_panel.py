"""The Mark dock: laser settings, the job's size and time, Preview (pilot laser), Mark with
progress and time left, and ABORT, which stops the laser before the next command. The
inspection goes to the camera dock: each mark read back (rectified onto the surface, the
plan over it, decoded and graded), or the camera's frame when it was not read."""

from __future__ import annotations

import time

from PySide6.QtWidgets import QMessageBox, QVBoxLayout, QWidget

from insitu.errors import InsituError

from insitu.marking import LaserParams, MarkJob, estimate_time
from insitu.services.mark import StationRun
from insitu.services.serials import is_templated
from insitu.ui.model import operations as ops
from insitu.ui.model import scene_data as sd
from insitu.ui.qt.forms import icon, load_form


class MarkPanel(QWidget):
    def __init__(self, window, parent=None):
        super().__init__(parent)
        self.window_ = window
        self.session = window.session
        self.ui = load_form("mark", self)
        QVBoxLayout(self).addWidget(self.ui)
        ui = self.ui
        ui.previewButton.clicked.connect(self.preview)
        ui.markButton.clicked.connect(self.mark)
        ui.abortButton.clicked.connect(self.abort)
        ui.abortButton.setIcon(icon("abort"))
        for spin in (ui.powerSpin, ui.frequencySpin, ui.speedSpin):
            spin.valueChanged.connect(self.refresh)
        self.session.plans_changed.connect(self.refresh)
        self.session.cloud_changed.connect(self.refresh)
        self.session.rig_changed.connect(self.refresh)
        window.runner.busy_changed.connect(self._busy)
        self._t0 = 0.0
        self.last_result = None
        self.last_readback = None
        self.refresh()

    def laser(self) -> LaserParams:
        ui = self.ui
        return LaserParams(power_pct=ui.powerSpin.value(), frequency_khz=ui.frequencySpin.value(),
                           mark_speed_mm_s=ui.speedSpin.value())

    def job(self) -> MarkJob | None:
        """The session's job with these laser settings, or None (nothing placed or refused)."""
        job = self.session.job()
        return None if job is None else job.model_copy(update={"laser": self.laser()})

    def refresh(self) -> None:
        job, station = self.job(), self.window_.station
        busy = self.window_.runner.running("mark") or self.window_.runner.running("preview")
        if job is None:
            refused = [p.error for p in self.session.plans if p.error]
            self.ui.jobLabel.setText(f"no job: {refused[0]}" if refused else
                                     "no job: place a pattern on a cloud")
        else:
            e = estimate_time(job, station.driver.timing if station else None)
            self.ui.jobLabel.setText(f"{len(job.paths)} paths, mark {e.mark_mm:.0f} mm, "
                                     f"about {e.total_s:.1f} s" + self._serial_note())
        ok = job is not None and station is not None and not busy
        self.ui.previewButton.setEnabled(ok)
        self.ui.markButton.setEnabled(ok)

    def _serial_note(self) -> str:
        """What the job's variable data shows: the next serial, as a preview."""
        if not is_templated(self.session.placements.items):
            return ""
        return (f"; serial {ops.preview_serial(self.window_.job_path())} shown as a preview "
                "(taken when marked)")

    def preview(self) -> None:
        job, station = self.job(), self.window_.station
        if job is None or station is None:
            return
        self.window_.runner.start("preview", lambda p, c, f: ops.preview(job, station),
                                  self._previewed, self._failed)

    def _previewed(self, trace) -> None:
        self.window_.view.set_lines("pilot", sd.segments(trace), sd.PILOT_COLOUR)
        self.window_.show_message("pilot preview drawn (red); the laser is off")

    def mark(self) -> None:
        job, station = self.job(), self.window_.station
        if job is None or station is None:
            return
        path, items = self.window_.job_path(), self.session.placements.items
        if is_templated(items):           # a new part: planned again with the serial it takes
            cloud, laser = self.session.cloud, self.laser()

            def work(progress, cancel, _f):
                return ops.mark_serial(items, cloud, laser, station, path, progress, cancel)
        else:
            try:
                choice = self.ask_resume(ops.unfinished(job, path))
            except InsituError as e:
                self.window_.show_error(str(e))
                return
            if choice is None:
                return

            plans, cloud = list(self.session.plans), self.session.cloud

            def work(progress, cancel, _f):
                return ops.mark(job, station, path, progress, cancel, outcomes=plans,
                                cloud=cloud, **choice)
        task = self.window_.runner.start("mark", work, self._marked, self._failed)
        if task is not None:
            self._t0 = time.perf_counter()
            self.ui.progressBar.setValue(0)
            self.ui.resultLabel.setText("marking…")
            task.progress.connect(self._progress)

    def ask_resume(self, s) -> dict | None:
        """For an unfinished earlier run ``s`` of this job (a journal summary; None: none), ask
        how to go on: resume (a cut path marked again, skipped or continued) or start over.
        Returns the keywords of :func:`ops.mark`, or None when the operator cancels."""
        if s is None:
            return {}
        box = QMessageBox(QMessageBox.Icon.Question, "Unfinished job",
                          f"This job was {s.state} after {len(s.done)} of {s.paths_total} "
                          "paths.", QMessageBox.StandardButton.Cancel, self)
        if s.cut is None:
            choices = {"Resume": {"resume": True}}
        else:
            pos = ("the board reported no position" if s.cut_position is None else
                   f"the board reported {s.cut_position} marks done")
            box.setInformativeText(f"Path {s.cut + 1} was started but not confirmed ({pos}).")
            choices = {"Mark the cut path again": {"resume": True, "cut_path": "remark"},
                       "Skip the cut path": {"resume": True, "cut_path": "skip"},
                       "Continue the cut path": {"resume": True, "cut_path": "continue"}}
        choices["Start over"] = {"restart": True}
        buttons = {box.addButton(text, QMessageBox.ButtonRole.AcceptRole): kw
                   for text, kw in choices.items()}
        box.exec()
        return buttons.get(box.clickedButton())

    def abort(self) -> None:
        self.window_.runner.cancel("mark")
        self.ui.resultLabel.setText("aborting: laser off")

    def _progress(self, done: int, total: int) -> None:
        self.ui.progressBar.setMaximum(total)
        self.ui.progressBar.setValue(done)
        elapsed = time.perf_counter() - self._t0
        left = elapsed / max(done, 1) * (total - done)
        self.ui.timeLabel.setText(f"path {done} of {total}, about {left:.1f} s left")

    def _marked(self, outcome: StationRun) -> None:
        self.last_result = outcome.result
        r = outcome.result
        self.ui.resultLabel.setText(f"{r.state}: paths {r.completed} of {r.total} marked; "
                                    "the laser is off")
        rb = self.last_readback = outcome.readback
        if rb is None:
            self.window_.camera_image.show_image(outcome.image, None, "inspection: marked part")
        else:                                   # each mark rectified, the plan over it
            read = ", ".join(f"{r.decoded or 'NOT decoded'} {'=' if r.ok else '!='} plan"
                             if r.text is not None else ("in place" if r.ok else "off plan")
                             for r in rb.readings)
            self.window_.camera_image.show_image(rb.picture, None, f"inspection: {read}")
        self.window_.show_message(f"marking {r.state}")

    def _failed(self, message: str, _cancelled: bool) -> None:
        self.ui.resultLabel.setText(f"{message} (the laser is off)")
        self.window_.show_error(message)

    def _busy(self, name: str, busy: bool) -> None:
        if name in ("mark", "preview"):
            self.ui.abortButton.setEnabled(self.window_.runner.running("mark"))
            self.refresh()
