"""The main window's project files: New, Open (projects, clouds, jobs: :mod:`.open_files`),
Save, Save as, recent files, unsaved changes asked about and marked in the title bar (``*``),
where each job and its journal are kept — beside the project, or in the working folder while
the project was never saved (:mod:`insitu.ui.model.work_folder`) — and, at start, the last
job marked when it did not finish (Resume in the Mark dock)."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QFileDialog

from insitu.errors import InsituError
from insitu.formats.project import SUFFIX, Project, beside
from insitu.marking import journal_path_for, read_job
from insitu.services.project import OpenedProject, open_project, save_project
from insitu.services.serials import is_templated
from insitu.ui.model import operations as ops
from insitu.ui.model.work_folder import is_unsaved_job
from insitu.ui.qt import open_files
from insitu.ui.qt.dialogs import ask_save

MAX_RECENT = 8
UNSAVED = "unsaved project"


class ProjectFiles:
    """A mixin of :class:`~insitu.ui.qt.main_window.MainWindow` (its session, settings,
    runner, panels and status bar)."""

    # -- where jobs are kept ---------------------------------------------------------------
    def job_path(self) -> Path | None:
        """The job beside the saved project (None: never saved)."""
        p = self.session.project_path
        return None if p is None else beside(p, ".job.json")

    def work_folder(self) -> Path:
        """The working folder of a project never saved: its jobs and their journals."""
        return Path(self.settings.fileName()).resolve().parent / "unsaved"

    def last_job(self) -> Path | None:
        """The job this application marked last (its journal beside it), or None."""
        v = self.settings.value("last_job", "")
        return Path(v) if v else None

    def show_journal_place(self) -> None:
        """The status bar names where the job's journal is kept."""
        jf, saved = self.session.job_file, self.job_path()
        if jf is not None:
            where = journal_path_for(jf.path)
            text = f"journal: {where.name}"
        elif saved is not None or is_templated(self.session.placements.items):
            where = journal_path_for(saved) if saved else None
            text = f"journal: {where.name}" if where else "journal: save the project"
        else:
            where = self.work_folder()
            text = f"{UNSAVED}: journal in {where}"
        unsaved = where is not None and (where == self.work_folder()
                                         or is_unsaved_job(where, self.work_folder()))
        self.journal_label.set_text(text, f"every job marked is journaled from its first path: "
                                          f"{where}" + (" — the working folder of a project "
                                                        "never saved" if unsaved else ""))

    def restore_unfinished(self) -> None:
        """At start: open the job marked last when its journal says it did not finish, so
        that Resume (Mark dock) finishes it; a message says so."""
        path = self.last_job()
        if path is None or not path.exists():
            return

        def read(_p, _c, _f):
            job = read_job(path)
            return job, ops.unfinished(job, path)

        def opened(result) -> None:
            job, s = result
            if s is None or self.session.placements.items or self.session.job_file:
                return
            open_files.job_opened(self, path, job)
            text = (f"the last job marked ({path.name}) was {s.state} after {len(s.done)} of "
                    f"{s.paths_total} paths: Resume finishes it")
            self.mark_panel.tell(text)
            self.show_message(text, "restore")
        self.runner.start("restore", read, opened, lambda m, _c: None)

    # -- unsaved changes -------------------------------------------------------------------
    def _kept_state(self) -> dict:
        """What a project file keeps of the session (see :class:`SavedState`)."""
        s = self.session
        return {"placements": s.placements.items, "cloud": s.cloud, "pens": s.pens,
                "height calibration": s.height_cal_path, "field correction": s.field_path,
                "camera calibration": s.camera_cal_path,
                "scan settings": self.scan_panel.settings()}

    def update_title(self) -> None:
        """The project's name in the title bar, ``*`` while it has unsaved changes."""
        p = self.session.project_path
        self.setWindowTitle(f"insitu — {p.name if p else UNSAVED}[*]")
        self.setWindowModified(self.saved.dirty())

    def may_discard(self, what: str) -> bool:
        """True when the session may be replaced (``what``: "quitting", …): nothing unsaved,
        or the operator saved it or chose to discard it."""
        if not self.saved.dirty():
            return True
        answer = ask_save(self, self.saved.changes(), what)
        return answer == "discard" or (answer == "save" and self.save())

    def _clean(self) -> None:
        self.saved.mark_clean()
        self.update_title()
        self.show_journal_place()

    # -- new, open, save -------------------------------------------------------------------
    def new_project(self) -> None:
        if not self.may_discard("starting a new project"):
            return
        self.session.set_job_file(None)
        self.session.set_cloud(None)
        self.session.placements.reset()
        self.session.project_path = None
        self._clean()

    def _open_dialog(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Open", "", open_files.OPEN_FILTERS)
        if path:
            self.open_file(Path(path))

    def open_file(self, path: Path) -> None:
        """Open a project, a point cloud or a mark job (by its name), after asking to save
        unsaved changes where it replaces them."""
        open_files.open_file(self, path)

    def _export_dialog(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Export job", "", open_files.JOB_FILES)
        if path:
            open_files.export_job(self, Path(path if path.endswith(".json") else
                                             path + ".json"))

    def _save_dialog(self) -> None:
        path, _ = QFileDialog.getSaveFileName(self, "Save project", "", open_files.PROJECT_FILES)
        if path:
            self.save(Path(path if path.endswith(SUFFIX) else path + SUFFIX))

    def open_project(self, path: Path) -> None:
        self.runner.start("open", lambda p, c, f: open_project(path, p),
                          lambda opened: self._opened(path, opened),
                          lambda m, _c: self.show_error(m, "open"))

    def _opened(self, path: Path, opened: OpenedProject) -> None:
        from insitu.ui.qt.rig_connection import age_text

        pr, s = opened.project, self.session
        s.project_path = path
        s.height_cal_path, s.height_cal = pr.height_cal, opened.height_cal
        s.field_path, s.camera_cal_path = pr.field_correction, pr.camera_cal
        self.disconnect_rig()           # its rig and field correction: when the operator connects
        s.rig_choice = pr.rig
        self._rig_named()
        self.scan_panel.show_settings(pr.scan)
        self.scan_panel.ui.heightCalEdit.setText(str(pr.height_cal or ""))
        if opened.height_cal is not None:
            self.calib_label.setText(f"height calibration {age_text(opened.height_cal.created)}")
        self.binding.show_region(pr.scan.region)
        s.set_job_file(None)
        s.set_cloud(opened.cloud, pr.cloud)
        s.set_pens(pr.pens)
        s.placements.reset(pr.placements)
        s.select(pr.selected)
        self._clean()
        self._remember(path)
        self.show_message(f"opened {path}; rig not connected: "
                          f"{self.connect_action.text().replace('&', '')} (Rig menu)", "rig")

    def save(self, path: Path | None = None) -> bool:
        """Save the session to ``path`` (default: where it came from); True when written."""
        path = path or self.session.project_path
        if path is None:
            self._save_dialog()
            return self.session.project_path is not None
        s = self.session
        project = Project(s.rig_choice, s.height_cal_path, s.field_path, s.camera_cal_path,
                          self.scan_panel.settings(), s.cloud_path, s.placements.items,
                          s.selected, None, s.pens)
        # a job with variable data is written when it is marked, with the serial it takes
        job = None if is_templated(s.placements.items) else self.mark_panel.job()
        try:
            written = save_project(path, project, s.cloud, job)
        except InsituError as e:
            self.show_error(str(e), "save")
            return False
        s.project_path = path
        s.cloud_written(written.cloud)
        self._clean()
        self._remember(path)
        self.show_message(f"saved {path}", "save")
        return True

    # -- recent files ----------------------------------------------------------------------
    def _remember(self, path: Path) -> None:
        recent = [str(path)] + [p for p in self.recent_files() if p != str(path)]
        self.settings.setValue("recent_projects", recent[:MAX_RECENT])
        self._update_recent()

    def recent_files(self) -> list[str]:
        v = self.settings.value("recent_projects", [])
        return [v] if isinstance(v, str) else list(v or [])

    def _update_recent(self) -> None:
        self.recent_menu.clear()
        for p in self.recent_files():
            self.recent_menu.addAction(p, lambda p=p: self.open_file(Path(p)))
        self.recent_menu.setEnabled(bool(self.recent_files()))

