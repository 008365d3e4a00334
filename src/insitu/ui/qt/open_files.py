"""File ▸ Open… of the files the commands make — a project, a point cloud (``.ply``: the
session's cloud), a mark job (``job.json``: shown in the view and marked as ``insitu job run``
marks it, its journal beside it) — and File ▸ Export job… of the current plan."""

from __future__ import annotations

from pathlib import Path

from insitu.errors import InsituError
from insitu.formats.project import SUFFIX
from insitu.ui.model import scene_data as sd
from insitu.ui.model.session import JobFile

PROJECT_FILES = f"insitu projects (*{SUFFIX})"
CLOUD_FILES = "Point clouds (*.ply)"
JOB_FILES = "Mark jobs (*.json)"
OPEN_FILTERS = ";;".join([f"insitu files (*{SUFFIX} *.ply *.json)", PROJECT_FILES, CLOUD_FILES,
                          JOB_FILES])


def kind_of(path: Path) -> str | None:
    """"project", "cloud" or "job" by the file's name; None: none of them."""
    if path.name.endswith(SUFFIX):
        return "project"
    return {".ply": "cloud", ".json": "job"}.get(path.suffix.lower())


def open_file(window, path: Path) -> None:
    """Open ``path`` in ``window`` (a MainWindow) after asking to save unsaved changes; read
    off the GUI thread; a bad file is one line in the status bar and changes nothing."""
    kind = kind_of(path)
    if kind is None:
        window.show_error(f"{path}: expected a project (*{SUFFIX}), a point cloud (.ply) or a "
                          "mark job (.json)")
        return
    if not window.may_discard(f"opening {path.name}"):
        return
    if kind == "project":
        window.open_project(path)
    elif kind == "cloud":
        from insitu.formats.pointcloud import read_ply
        window.runner.start("open", lambda p, c, f: read_ply(path),
                            lambda cloud: _cloud_opened(window, path, cloud),
                            lambda m, _c: window.show_error(m))
    else:
        from insitu.marking import read_job
        window.runner.start("open", lambda p, c, f: read_job(path),
                            lambda job: job_opened(window, path, job),
                            lambda m, _c: window.show_error(m))


def _cloud_opened(window, path: Path, cloud) -> None:
    s = window.session
    s.set_job_file(None)
    s.set_cloud(cloud, path)
    window._remember(path)
    window.show_message(f"opened {path}: {len(cloud):,} points; the session's cloud")


def job_opened(window, path: Path, job) -> None:
    s = window.session
    s.placements.reset()
    s.set_job_file(JobFile(path, job))
    window.saved.mark_clean()
    window._remember(path)
    window.docks["mark"].raise_()
    window.show_message(f"opened job {path}: {len(job.paths):,} paths; Mark checks it against "
                        "the rig and its journal, as insitu job run does")


def show_job_file(window) -> None:
    """Draw the opened job's paths (magenta, as projected paths), or nothing."""
    jf = window.session.job_file
    lines = sd.segments([p.points for p in jf.job.paths] if jf is not None else [])
    window.view.set_lines("job", lines, sd.PROJECTED_COLOUR)
    if len(lines) and window.session.cloud is None:
        window.view.frame_all(lines.min(0), lines.max(0))


def export_job(window, path: Path) -> bool:
    """Write the current plan as a mark job at ``path`` (atomically); False and one line
    when there is none."""
    from insitu.services.serials import is_templated, save_job

    job = window.mark_panel.job()
    if window.session.job_file is None and is_templated(window.session.placements.items):
        window.show_error("export job: a job with variable data is written when it is marked "
                          "(it takes its serial then)")
        return False
    if job is None:
        window.show_error("export job: no job to export: place a pattern on a cloud (none "
                          "refused)")
        return False
    try:
        save_job(path, job)
    except InsituError as e:
        window.show_error(str(e))
        return False
    window.show_message(f"exported {path}: {len(job.paths):,} paths")
    return True
