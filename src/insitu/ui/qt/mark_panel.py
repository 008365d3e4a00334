"""The Mark dock: the pens, the job's size and time, Preview (pilot laser), Mark — armed
first (what will be marked, confirmed by the operator) — with progress and time left, Resume
of an unfinished job, and ABORT, which stops the laser before the next command. The
inspection goes to the camera dock: each mark read back (rectified onto the surface, the
plan over it, decoded and graded), or the camera's frame when it was not read."""

from __future__ import annotations

import time
from pathlib import Path

from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QHBoxLayout, QMessageBox, QPushButton, QVBoxLayout, QWidget

from insitu.errors import InsituError
from insitu.marking import JournalSummary, LaserParams, MarkJob, path_seconds
from insitu.services.mark import StationRun, board_seconds
from insitu.services.serials import is_templated
from insitu.ui.model import operations as ops
from insitu.ui.model import scene_data as sd
from insitu.ui.model.arming import arm_rows
from insitu.ui.model.time_left import TimeLeft
from insitu.ui.model.work_folder import is_unsaved_job, prune, unsaved_job_path
from insitu.ui.qt.dialogs import ArmDialog
from insitu.ui.qt.forms import icon, load_form
from insitu.ui.qt.pens_panel import PensRow
from insitu.ui.qt.place_panel import short_name

BUSY = ("mark", "preview", "scan", "produce", "engrave")
"""Tasks that use the station: none of them starts while another runs."""


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
        self.resume_button = QPushButton("Resume", ui)
        self.resume_button.setObjectName("resumeButton")
        self.resume_button.setToolTip("Continue the unfinished job its journal records")
        ui.findChild(QHBoxLayout, "buttons").insertWidget(2, self.resume_button)
        self.resume_button.clicked.connect(self.resume)
        ui.abortButton.clicked.connect(self.abort)
        ui.abortButton.setIcon(icon("abort"))
        self._laser_actions(window)
        self.pens_row = PensRow(self.session, self)     # each placement's pen sets its laser
        ui.layout().insertWidget(0, self.pens_row)
        ui.laserBox.hide()
        for spin in (ui.powerSpin, ui.frequencySpin, ui.speedSpin):
            spin.valueChanged.connect(self.refresh)
        self.session.plans_changed.connect(self.refresh)
        self.session.cloud_changed.connect(self.refresh)
        self.session.rig_changed.connect(self.refresh)
        self.session.pens_changed.connect(self.refresh)
        self.session.job_file_changed.connect(self.refresh)
        window.runner.busy_changed.connect(self._busy)
        self._t0 = 0.0
        self._time_left: TimeLeft | None = None
        self.arm_dialog: ArmDialog | None = None
        self._armed: str | None = None          # the armed job's digest
        self._armed_path: Path | None = None    # where the armed run is journaled
        self._result_of: str | None = None      # the digest of the job the result is of
        self.last_result = None
        self.last_readback = None
        self.refresh()

    def laser(self) -> LaserParams:
        ui = self.ui
        return LaserParams(power_pct=ui.powerSpin.value(), frequency_khz=ui.frequencySpin.value(),
                           mark_speed_mm_s=ui.speedSpin.value())

    def job(self) -> MarkJob | None:
        """The opened job file's job as it is, else the session's job with these laser
        settings, or None (nothing placed or refused)."""
        if self.session.job_file is not None:
            return self.session.job_file.job
        job = self.session.job()
        return None if job is None else job.model_copy(update={"laser": self.laser()})

    def _laser_actions(self, window) -> None:
        """Preview (the red pilot light, F1), Mark (F2), Resume and ABORT (Esc, Space; only
        while marking) as the window's actions: the Laser menu, the toolbar, Help."""
        def action(text, slot, keys=(), icon_name=None) -> QAction:
            a = QAction(text, window)
            a.setShortcuts([QKeySequence(k) for k in keys])
            a.triggered.connect(slot)
            if icon_name:
                a.setIcon(icon(icon_name))
            return a
        self.preview_action = action("&Preview (red light)", self.preview, ["F1"])
        self.mark_action = action("&Mark…", self.mark, ["F2"], "mark")
        self.resume_action = action("&Resume…", self.resume)
        self.abort_action = action("&ABORT", self.abort, ["Esc", "Space"], "abort")
        self.abort_action.setEnabled(False)
        self.ui.previewButton.setToolTip("the red pilot light traces the job's outline (F1)")
        self.ui.markButton.setToolTip("arm the job: what will be marked, then Fire laser (F2)")
        self.ui.abortButton.setToolTip("stop the board at once, laser off (Esc or Space)")

    def job_path(self) -> Path | None:
        """Where the job is kept, its journal beside it: the opened job file, else beside the
        project, else — a project never saved — in the working folder (a job with variable
        data needs the project: its serial counter is kept beside it)."""
        jf = self.session.job_file
        if jf is not None:
            return jf.path
        saved = self.window_.job_path()
        if saved is not None or is_templated(self.session.placements.items):
            return saved
        job = self.job()
        return None if job is None else unsaved_job_path(self.window_.work_folder(), job)

    def unfinished_run(self, job: MarkJob | None) -> tuple[Path, JournalSummary] | None:
        """(where, summary) of an unfinished earlier run of ``job``: beside its job file, or
        where this application marked it last (a project saved after its job was marked in
        the working folder); None: none. InsituError for an unreadable journal beside it."""
        if job is None or (self.session.job_file is None
                           and is_templated(self.session.placements.items)):
            return None
        own = self.job_path()
        for where in dict.fromkeys([own, self.window_.last_job()]):
            try:
                s = ops.unfinished(job, where)
            except InsituError:
                if where == own:
                    raise
                continue
            if s is not None:
                return where, s
        return None

    def refresh(self) -> None:
        job, station = self.job(), self.window_.station
        busy = any(self.window_.runner.running(n) for n in BUSY)
        digest = None if job is None else job.digest()
        if self._armed is not None and digest != self._armed:
            self.disarm("disarmed: the job changed")
        if not busy and digest != self._result_of:   # a result is of the job it was, only
            self._result_of = None
            self.ui.resultLabel.setText("")
            self.ui.timeLabel.setText("")
            self.ui.progressBar.setValue(0)
        if job is None:
            refused = [(i, p.error) for i, p in enumerate(self.session.plans) if p.error]
            self.ui.jobLabel.setText(f"no job: placement {refused[0][0] + 1} refused: "
                                     f"{refused[0][1]}" if refused else
                                     "no job: place a pattern on a cloud")
        else:
            t = board_seconds(job, station)
            jf = self.session.job_file
            self.ui.jobLabel.setText((f"job file {jf.path.name}: " if jf else "")
                                     + f"{len(job.paths)} paths, mark {t.mark_mm:.0f} mm, "
                                     f"{t.words()}" + self._serial_note())
        ok = job is not None and station is not None and not busy and self._armed is None
        try:
            unfinished = ok and self.unfinished_run(job) is not None
        except InsituError:
            unfinished = False
        for button, action, on in ((self.ui.previewButton, self.preview_action,
                                    job is not None and station is not None and not busy),
                                   (self.ui.markButton, self.mark_action, ok),
                                   (self.resume_button, self.resume_action, unfinished)):
            button.setEnabled(on)
            action.setEnabled(on)

    def _serial_note(self) -> str:
        """What the job's variable data shows: the next serial, as a preview."""
        if self.session.job_file is not None or not is_templated(self.session.placements.items):
            return ""
        return (f"; serial {ops.preview_serial(self.window_.job_path())} shown as a preview "
                "(taken when marked)")

    def tell(self, text: str) -> None:
        """``text`` in the result line, for as long as the job shown is this one."""
        job = self.job()
        self._result_of = None if job is None else job.digest()
        self.ui.resultLabel.setText(text)

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
        """Arm the job (after asking how to go on with an unfinished earlier run of it)."""
        self._arm(resume_only=False)

    def resume(self) -> None:
        """Arm the unfinished job its journal records, after asking how to go on."""
        self._arm(resume_only=True)

    def _arm(self, resume_only: bool) -> None:
        job, station = self.job(), self.window_.station
        if job is None or station is None or self._armed is not None:
            return
        summary, choice, where = None, {}, self.job_path()
        if self.session.job_file is not None or not is_templated(self.session.placements.items):
            try:
                found = self.unfinished_run(job)
            except InsituError as e:
                self.window_.show_error(str(e), "mark")
                return
            if resume_only and found is None:
                return
            if found is not None:
                where, summary = found
            choice = self.ask_resume(summary)
            if choice is None:
                return
        first = 0
        if summary is not None and choice.get("resume"):
            first = len(summary.done | summary.skipped)
        names = [short_name(p.pattern) for p in self.session.placements.items
                 if self.session.job_file is None]
        rows = arm_rows(job, names, " · ".join(station.describe()), board_seconds(
            job, station, first), first, where, choice,
            unsaved=is_unsaved_job(where, self.window_.work_folder()))
        self._armed = self._result_of = job.digest()
        self._armed_path = where
        self.arm_dialog = dlg = ArmDialog(rows, self)
        dlg.accepted.connect(lambda: self._fire(job, choice, first))
        dlg.rejected.connect(lambda: self.disarm("disarmed: nothing was marked"))
        self.ui.resultLabel.setText("armed: confirm in the dialog (Esc disarms)")
        self.refresh()
        dlg.open()

    def disarm(self, why: str) -> None:
        """Forget the armed job (its dialog closed); ``why`` shown."""
        dlg, self.arm_dialog, self._armed = self.arm_dialog, None, None
        if dlg is not None:
            dlg.dismiss()
            job = self.job()
            self._result_of = None if job is None else job.digest()
            self.ui.resultLabel.setText(why)
            self.refresh()

    def _fire(self, job: MarkJob, choice: dict, first: int) -> None:
        """The operator confirmed: mark ``job`` — if it is still the armed one and the
        station still connected."""
        armed, station, path = self._armed, self.window_.station, self._armed_path
        if self.arm_dialog is not None:
            self.arm_dialog.deleteLater()
        self.arm_dialog, self._armed = None, None
        current = self.job()
        if current is None or current.digest() != armed or station is None:
            self.ui.resultLabel.setText("disarmed: the job or the station changed; nothing "
                                        "was marked")
            self.refresh()
            return
        items = self.session.placements.items
        if path is not None and is_unsaved_job(path, self.window_.work_folder()):
            path.parent.mkdir(parents=True, exist_ok=True)
            prune(path.parent)
        if self.session.job_file is None and is_templated(items):
            cloud, laser = self.session.cloud, self.laser()   # planned again with its serial
            pens = self.session.pens

            def work(progress, cancel, _f):
                return ops.mark_serial(items, cloud, laser, station, path, progress, cancel,
                                       pens)
        else:
            write = self.session.job_file is None       # an opened job file: marked as is
            plans = list(self.session.plans) if write else None     # what is read back
            cloud = self.session.cloud

            def work(progress, cancel, _f):
                return ops.mark(job, station, path, progress, cancel, write=write,
                                outcomes=plans, cloud=cloud, **choice)
        task = self.window_.runner.start("mark", work, self._marked, self._failed)
        if task is not None:
            if path is not None:
                self.window_.settings.setValue("last_job", str(path))
            self._t0 = time.perf_counter()
            self._time_left = TimeLeft(path_seconds(job, station.driver.timing), first,
                                       station.mark_pace or 1.0)
            self._result_of = armed
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
        """ABORT: the board stops at once, laser off (the journal records the cut path); an
        engraving under way (the Engrave dock) stops as well."""
        if self.window_.runner.running("mark"):
            self.window_.runner.cancel("mark")
            self.ui.resultLabel.setText("aborting: laser off")
        self.window_.engrave_panel.abort()

    def _progress(self, done: int, total: int) -> None:
        self.ui.progressBar.setMaximum(total)
        self.ui.progressBar.setValue(done)
        left = self._time_left.update(done, time.perf_counter() - self._t0)
        self.ui.timeLabel.setText(f"path {done} of {total}, "
                                  + (f"about {left:.0f} s left" if left >= 0.5 else "finishing"))

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
        self.window_.show_message(f"marking {r.state}: {r.completed} of {r.total} paths", "mark")

    def _failed(self, message: str, _cancelled: bool) -> None:
        self.ui.resultLabel.setText(f"{message} (the laser is off)")
        self.window_.show_error(message, "mark")

    def _busy(self, name: str, busy: bool) -> None:
        if name in BUSY:
            marking = self.window_.runner.running("mark")
            self.ui.abortButton.setEnabled(marking)
            self.abort_action.setEnabled(marking or self.window_.runner.running("engrave"))
            self.pens_row.set_locked(marking)
            self.window_.place_panel.pen_chooser.set_locked(marking)
            self.refresh()
