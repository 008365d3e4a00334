"""The marking service that the commands and the GUI share: every placement planned (a
refusal kept with its place), cancelling before the next command with the laser off, and
marking on the station with its progress file and the image of the part."""

import threading

import numpy as np
import pytest

from insitu.devices.galvo import RecordingController
from insitu.formats.pointcloud import PointCloud
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import (
    GalvoDriver,
    Placement,
    make_job,
    progress_path_for,
    read_progress,
    write_job,
)
from insitu.services import Cancelled
from insitu.services.mark import mark, mark_on_station
from insitu.services.plan import plan_placements
from insitu.services.station import connect

HEAD = TwoMirrorHead(350.0, 12.0)


def paths_job(n=4):
    return make_job([np.array([[x, -3.0, 0.5], [x, 3.0, 0.5], [x + 0.5, 3.0, 0.5]])
                     for x in np.linspace(-10, 10, n)])


class BoardLike(RecordingController):
    """Runs each list command by command as a board does, until ``laser_off`` (from any
    thread) stops it; sets ``cancel`` once it has executed ``n`` commands and goes on
    until it is stopped."""

    def __init__(self, n: int, cancel: threading.Event):
        super().__init__()
        self.n, self.cancel, self.stopped = n, cancel, threading.Event()
        self.lists = 0

    def execute(self, commands):
        self.stopped.clear()
        self.lists += 1
        for c in commands:
            if self.stopped.is_set():
                break
            super().execute([c])
            if len(self.commands) == self.n:
                self.cancel.set()
                assert self.stopped.wait(2.0), "the abort did not stop the board"

    def laser_off(self):
        self.stopped.set()
        super().laser_off()


def test_each_placement_is_planned_and_a_refusal_kept_where_it_is(tmp_path):
    with connect(binning=4) as station:
        xs, ys = np.meshgrid(np.linspace(80, 120, 60), np.linspace(-10, 10, 30))
        cloud = PointCloud(np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)])
        out = plan_placements(cloud, [Placement('text:"A"', (99.0, 0.0), 8.0),
                               Placement(str(tmp_path / "gone.svg"), (90.0, 0.0), 4.0),
                               Placement('text:"A"', (90.0, 0.0), 4.0)], station.driver)
    assert out[0].plan is None and "outside the scan field" in out[0].error
    assert out[0].where is not None and out[0].where[0] > 100.0
    assert out[1].plan is None and out[1].where is None and "gone.svg" in out[1].error
    assert out[2].error is None and len(out[2].plan.job.paths) > 0


def test_cancel_within_a_path_stops_the_board_at_once_with_the_laser_off(tmp_path):
    job, cancel = paths_job(), threading.Event()
    lists = GalvoDriver(HEAD).compile(job)
    cut = sum(map(len, lists[:2])) + 3                 # inside path 2, the laser on
    controller = BoardLike(cut, cancel)
    write_job(tmp_path / "job.json", job)
    ppath = progress_path_for(tmp_path / "job.json")
    with pytest.raises(Cancelled):
        mark(job, GalvoDriver(HEAD), controller, ppath, cancel=cancel)
    assert len(controller.commands) == cut and controller.commands == sum(lists, [])[:cut]
    # each path went to the board as one list (a board enables its laser per list)
    assert controller.lists == 3
    assert not controller.laser_is_on and controller.off_calls >= 1
    rec = read_progress(ppath)
    assert rec["state"] == "interrupted" and rec["completed"] == 2   # path 2 not completed


def test_cancel_between_paths_ends_the_run_cancelled(tmp_path):
    job, cancel = paths_job(), threading.Event()
    lists = GalvoDriver(HEAD).compile(job)
    controller = BoardLike(10**9, cancel)

    def after(done, total):
        cancel.set()                                    # the operator, between two paths

    result = mark(job, GalvoDriver(HEAD), controller, tmp_path / "p.json", cancel=cancel,
                  progress=after)
    assert (result.state, result.completed) == ("cancelled", 1)
    assert controller.commands == lists[0] and not controller.laser_is_on


def test_mark_on_the_station_records_progress_and_images_the_part(tmp_path):
    job = make_job([np.array([[-2.0, 30.0, 5.0], [2.0, 30.0, 5.0]])])
    job_path, png = tmp_path / "j.json", tmp_path / "inspect.png"
    write_job(job_path, job)
    with connect(binning=4) as station:
        run = mark_on_station(station, job, job_path, inspect=png)
        quiet = mark_on_station(station, job, None)
    assert run.result.state == "done" and run.progress_path == progress_path_for(job_path)
    assert read_progress(run.progress_path)["state"] == "done"
    assert run.image is not None and run.image.ndim == 2 and png.stat().st_size > 0
    assert quiet.progress_path is None and quiet.image is None and quiet.result.completed == 1


def test_the_boards_pace_from_its_runs_sets_the_next_estimate():
    """A board that took 4 × the plan's seconds: the next job's estimate and the first
    time-left figure are 4 × the plan's, said so in words."""
    from types import SimpleNamespace

    from insitu.marking import RunResult, estimate_time, path_seconds
    from insitu.services.mark import _learn_pace, board_seconds
    from insitu.ui.model.time_left import TimeLeft

    job = make_job([np.array([[x, 0, 0], [x, 40, 0.0]]) for x in range(20)])
    driver = GalvoDriver(TwoMirrorHead(350.0, 12.0))
    station = SimpleNamespace(driver=driver, mark_pace=None)
    plan = estimate_time(job, driver.timing).total_s
    assert board_seconds(job, station).total_s == pytest.approx(plan)
    _learn_pace(station, job, RunResult("done", 20, 20, 0), 0, 4.0 * plan)
    assert station.mark_pace == pytest.approx(4.0)
    t = board_seconds(job, station)
    assert t.total_s == pytest.approx(4.0 * plan) and "pace: 4.0 ×" in t.words()
    left = TimeLeft(path_seconds(job, driver.timing), 0, station.mark_pace)
    assert left.update(1, 4.0 * float(path_seconds(job, driver.timing)[0])) == \
        pytest.approx(4.0 * plan * 19 / 20, rel=0.05)
    _learn_pace(station, job, RunResult("done", 20, 20, 0), 0, 2.0 * plan)
    assert station.mark_pace == pytest.approx(3.0)          # remembered, not replaced
