"""A job that survives faults: the device stops answering at a random point of a long job
(the fake RTC library stops answering after n calls; the fake LMC board is unplugged after n
USB transfers), hundreds of times. Each time: the laser is off, the journal records the paths
done and the cut one (with the marks the board reported done), a resume without a choice for
the cut path refuses, and resuming on the reconnected device (the cut path marked again, or
continued from the reported mark on the RTC) completes the pattern exactly — every segment
marked, no completed path marked again, nothing beyond the cut path marked before the resume.
"""

import os
import shutil
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from fakes.lmc_usb import FakeLmcBoard
from fakes.rtc import FakeBoard, build
from fakes.station import allow
from insitu.devices.lmc import LmcController, LmcSettings
from insitu.devices.rtc import RtcController, RtcSettings
from insitu.errors import DeviceError, SafetyError
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import GalvoDriver, history, make_job, read_progress, run_job

HEAD = TwoMirrorHead(350.0, 12.0)
RUNS_PER_DEVICE = 200


def long_job(n_paths=40):
    rng = np.random.default_rng(7)
    paths = []
    for _ in range(n_paths):
        k = int(rng.integers(2, 6))
        xy = rng.uniform(-8, 8, (k, 2))
        paths.append(np.column_stack([xy, np.zeros(k)]))
    return make_job(paths)


class RtcRig:
    def __init__(self, lib, folder):
        cor = folder / "head.ct5"
        cor.write_bytes(b"\0")
        self.settings = RtcSettings(library=lib, correction_file=cor, k_bits_per_mm=2000.0,
                                    heartbeat_s=30.0)
        self.board = FakeBoard(lib)

    def connect(self, fail_after=None):
        """A fresh connection to a reset board, failing after ``fail_after`` library calls."""
        self.board.reset()
        ctrl = RtcController(HEAD, self.settings, poll_s=0.0)
        if fail_after is not None:
            self.board.fail_after(fail_after)
        return ctrl

    def segments(self):
        """[(list run, segment)] marked since the last connect."""
        return [(int(r[0]), tuple(r[1:])) for r in self.board.marks()]

    def laser_off(self):
        return not self.board.laser_enabled and self.board.port == 0

    def activity(self):
        return len(self.board.calls())


class LmcRig:
    def __init__(self):
        self.settings = LmcSettings(bits_per_deg=1500.0, heartbeat_s=30.0)

    def connect(self, fail_after=None):
        self.board = FakeLmcBoard()
        ctrl = LmcController(HEAD, self.settings, backend=self.board, poll_s=0.0)
        if fail_after is not None:
            self.board.unplug_after(fail_after)
        return ctrl

    def segments(self):
        return [(m[0], tuple(m[1:])) for m in self.board.marks]

    def laser_off(self):
        return not self.board.laser_output()

    def activity(self):
        return self.board.transfers


@pytest.fixture
def progress_dir(tmp_path):
    """Where progress files go: tmpfs when there is one (each path's record is fsynced, which
    on a disk would dominate hundreds of runs), else the test's tmp folder."""
    shm = Path("/dev/shm")
    if not (shm.is_dir() and os.access(shm, os.W_OK)):
        yield tmp_path
        return
    folder = Path(tempfile.mkdtemp(prefix="insitu-faults-", dir=shm))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.fixture(scope="module")
def rtc_lib(tmp_path_factory):
    return allow(build(tmp_path_factory.mktemp("rtc")))   # the station allows the fake


def per_path(segments, first_path):
    """{path index: [segments]} from (list run, segment); list run 1 is ``first_path``."""
    out = {}
    for run, seg in segments:
        out.setdefault(first_path + run - 1, []).append(seg)
    return out


def inject_faults(rig, tmp_path, runs, seed, choices=("remark",)):
    job, driver = long_job(), GalvoDriver(HEAD)
    clean = rig.connect()
    opened = rig.activity()
    run_job(job, driver, clean)
    n_calls = rig.activity() - opened             # calls (transfers) the job itself makes
    clean.close()
    want = per_path(rig.segments(), 0)
    assert len(want) == len(job.paths)
    rng = np.random.default_rng(seed)
    stats = Counter()
    for k in range(runs):
        prog = tmp_path / f"job{k}.progress.json"
        ctrl = rig.connect(fail_after=int(rng.integers(0, n_calls)))
        try:
            run_job(job, driver, ctrl, prog)
            stats["only the final laser-off lost"] += 1       # the job was complete
        except DeviceError:
            pass
        assert rig.laser_off(), f"run {k}: laser left on"
        ctrl.close()
        rec, journal = read_progress(prog), history(job, prog)
        if rec["state"] == "done":
            assert per_path(rig.segments(), 0) == want and journal.done == set(range(40))
            continue
        done = rec["completed"]
        assert rec["state"] == "interrupted" and rec["last_completed_path"] == (done - 1 if done
                                                                                else None)
        # the journal: paths before the cut one done, the cut one started and not confirmed
        assert journal.state == "interrupted" and journal.done == set(range(done))
        assert journal.cut == done == rec["cut_path"], f"run {k}: cut path not reported"
        first = per_path(rig.segments(), 0)
        for p in range(done):                           # completed paths: all of them
            assert first.get(p) == want[p], f"run {k}: path {p} not marked as recorded"
        cut = first.get(done, [])
        assert cut == want.get(done, [])[:len(cut)], f"run {k}: path {done} marked wrongly"
        assert max(first, default=-1) <= done, f"run {k}: marked beyond the cut path"
        marks = journal.cut_position                    # marks the board reported done
        assert marks is None or marks <= len(cut), f"run {k}: position beyond what was marked"
        stats["cut mid-path" if cut else "cut before its first mark"] += 1
        assert "does not respond" in rec["error"] or "unplugged" in rec["error"]
        # without a choice the resume refuses, naming the cut path; nothing is sent
        ctrl = rig.connect()
        with pytest.raises(SafetyError, match=f"path {done + 1} of 40 was started"):
            run_job(job, driver, ctrl, prog, resume=True)
        assert rig.segments() == []
        choice = choices[k % len(choices)] if marks is not None else "remark"
        stats[choice] += 1
        result = run_job(job, driver, ctrl, prog, resume=True, cut_path=choice)
        ctrl.close()
        assert result.state == "done" and result.cut == done and result.cut_choice == choice
        second = per_path(rig.segments(), result.start_path)
        assert min(second, default=done) >= done, f"run {k}: a completed path marked again"
        union = {p: (first.get(p, []) if p < done else second.get(p, []))
                 for p in range(len(job.paths))}
        if choice == "continue":                        # from the reported mark on
            assert second.get(done, []) == want[done][marks:], f"run {k}: not continued"
            union[done] = cut[:marks] + second.get(done, [])
        assert union == want, f"run {k}: the pattern is not complete after resuming"
        assert read_progress(prog)["state"] == "done" and history(job, prog).finished
    return stats


def _runs(stats):
    return stats["only the final laser-off lost"] + stats["cut mid-path"] + stats[
        "cut before its first mark"]


def test_rtc_board_stops_answering_at_random_points(rtc_lib, tmp_path, progress_dir):
    stats = inject_faults(RtcRig(rtc_lib, tmp_path), progress_dir, RUNS_PER_DEVICE, seed=1,
                          choices=("remark", "continue"))
    assert _runs(stats) == RUNS_PER_DEVICE and stats["cut mid-path"] > 10
    assert stats["continue"] > 10 and stats["remark"] > 10


def test_lmc_board_unplugged_at_random_points(progress_dir):
    stats = inject_faults(LmcRig(), progress_dir, RUNS_PER_DEVICE, seed=2)
    assert _runs(stats) == RUNS_PER_DEVICE and stats["cut mid-path"] > 10
