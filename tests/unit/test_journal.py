"""The journal of what the laser did: started / done / cut per path, refusals, the operator's
choice for a cut path (remark, skip, continue), malformed records (signals from outside:
tests/integration/test_kill_resume.py)."""

import json

import numpy as np
import pytest

from insitu.devices.galvo import ListPosition, RecordingController, list_digest
from insitu.errors import DeviceError, FormatError, SafetyError
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import (
    GalvoDriver,
    history,
    make_job,
    progress_path_for,
    read_journal,
    read_progress,
    run_job,
    write_job,
)
from insitu.marking.run import resume_list

HEAD = TwoMirrorHead(350.0, 12.0)


def job_of(n=5, points=6):
    t = np.linspace(0.0, 1.0, points)
    return make_job([np.column_stack([x + 2 * t, np.sin(3 * t), 0 * t])
                     for x in np.linspace(-10, 10, n)])


class Board(RecordingController):
    """Records commands; reports its position in the list it runs; raises ``exc`` at the
    ``fail_at``-th command overall. ``lists``: the lists it completed; ``marks``: every mark
    move executed, as its target."""

    def __init__(self, fail_at=None, exc=DeviceError, reports=True):
        super().__init__()
        self.fail_at, self.exc, self.reports = fail_at, exc, reports
        self.lists, self.marks, self.pos = [], [], None

    def execute(self, commands):
        digest = list_digest(commands)
        for i, c in enumerate(commands):
            if self.fail_at is not None and len(self.commands) == self.fail_at:
                raise self.exc("injected fault")
            super().execute([c])
            if c.op == "mark_abs_3d":
                self.marks.append(c.args)
            self.pos = ListPosition(digest, i + 1)
        self.lists.append(list(commands))

    def position(self):
        return self.pos if self.reports else None


def all_marks(job):
    return [c.args for cmds in GalvoDriver(HEAD).compile(job) for c in cmds
            if c.op == "mark_abs_3d"]


def cut_run(tmp_path, job, at, **kw):
    """Run ``job`` until a fault at command ``at``; returns (progress path, board)."""
    prog = progress_path_for(tmp_path / "job.json")
    board = Board(fail_at=at, **kw)
    with pytest.raises(DeviceError):
        run_job(job, GalvoDriver(HEAD), board, prog)
    return prog, board


def events(prog):
    jpath = prog.with_name(prog.name.replace(".progress.json", ".journal.jsonl"))
    return [json.loads(line) for line in jpath.read_text().splitlines()]


def test_started_is_on_disk_before_its_list_is_sent_and_done_after(tmp_path):
    job, prog = job_of(3), progress_path_for(tmp_path / "job.json")
    seen = []

    class Peeking(Board):
        def execute(self, commands):
            seen.append(events(prog)[-1])
            super().execute(commands)

    run_job(job, GalvoDriver(HEAD), Peeking(), prog)
    assert [(e["event"], e["path"]) for e in seen] == [("started", k) for k in range(3)]
    ev = events(prog)
    assert [e["event"] for e in ev] == ["begin"] + ["started", "done"] * 3 + ["end"]
    assert ev[0]["mode"] == "start" and ev[-1]["state"] == "done"
    assert read_progress(prog)["completed"] == 3 and read_progress(prog)["state"] == "done"


def test_a_fault_mid_path_leaves_a_cut_path_with_the_boards_position(tmp_path):
    job = job_of()
    lists = GalvoDriver(HEAD).compile(job)
    at = sum(map(len, lists[:2])) + 12                # the 12th command of path 2
    prog, board = cut_run(tmp_path, job, at)
    s = history(job, prog)
    marked = sum(c.op == "mark_abs_3d" for c in lists[2][:12])
    assert s.done == {0, 1} and s.cut == 2 and s.cut_position == marked > 0
    assert s.state == "interrupted" and "injected fault" in s.error
    assert events(prog)[-2] == {**events(prog)[-2], "event": "cut", "path": 2}
    rec = read_progress(prog)
    assert rec["completed"] == 2 and rec["cut_path"] == 2 and rec["cut_position"] == marked
    assert not board.laser_is_on and board.off_calls == 1


def test_resume_with_a_cut_path_refuses_without_a_choice_and_sends_nothing(tmp_path):
    job = job_of()
    lists = GalvoDriver(HEAD).compile(job)
    prog, _ = cut_run(tmp_path, job, sum(map(len, lists[:1])) + 9)
    board = Board()
    with pytest.raises(SafetyError, match=r"path 2 of 5 was started but not confirmed "
                                          r"\(the board reported \d+ marks done\): choose "
                                          "for the cut path remark"):
        run_job(job, GalvoDriver(HEAD), board, prog, resume=True)
    assert board.commands == []


def test_an_interrupted_job_is_not_run_again_without_resume_or_restart(tmp_path):
    job = job_of()
    prog, _ = cut_run(tmp_path, job, 40)
    board = Board()
    with pytest.raises(SafetyError, match="interrupted after 2 of 5 paths: resume it, or restart "
                                          "it"):
        run_job(job, GalvoDriver(HEAD), board, prog)
    assert board.commands == []
    n_lines = len(events(prog))
    result = run_job(job, GalvoDriver(HEAD), board, prog, restart=True)
    assert result.state == "done" and len(board.lists) == 5 and board.marks == all_marks(job)
    ev = events(prog)
    assert len(ev) > n_lines and ev[n_lines]["event"] == "begin"      # earlier runs kept
    assert ev[n_lines]["mode"] == "restart"
    s = history(job, prog)
    assert s.done == set(range(5)) and s.cut is None and s.state == "done"


def test_remark_marks_the_cut_path_again_and_never_a_done_one(tmp_path):
    job = job_of()
    lists = GalvoDriver(HEAD).compile(job)
    prog, first = cut_run(tmp_path, job, sum(map(len, lists[:3])) + 10)
    board = Board()
    r = run_job(job, GalvoDriver(HEAD), board, prog, resume=True, cut_path="remark")
    assert (r.state, r.start_path, r.cut, r.cut_choice) == ("done", 3, 3, "remark")
    fresh = GalvoDriver(HEAD).compile(job, first_path=3)
    assert board.lists == fresh
    assert history(job, prog).done == set(range(5))


def test_skip_leaves_the_cut_path_as_it_is(tmp_path):
    job = job_of()
    lists = GalvoDriver(HEAD).compile(job)
    prog, _ = cut_run(tmp_path, job, sum(map(len, lists[:1])) + 10)
    board = Board()
    r = run_job(job, GalvoDriver(HEAD), board, prog, resume=True, cut_path="skip")
    assert r.state == "done" and board.lists == GalvoDriver(HEAD).compile(job, first_path=2)
    s = history(job, prog)
    assert s.skipped == {1} and s.done == {0, 2, 3, 4} and s.finished
    assert read_progress(prog)["completed"] == 5 and read_progress(prog)["skipped_paths"] == [1]
    resumed = events(prog)[[e["event"] for e in events(prog)].index("begin", 1):]
    assert [(e["event"], e.get("path")) for e in resumed[:3]] == [
        ("begin", None), ("skipped", 1), ("started", 2)]


def test_continue_marks_the_rest_of_the_cut_path_from_the_reported_mark(tmp_path):
    job = job_of()
    lists = GalvoDriver(HEAD).compile(job)
    prog, first = cut_run(tmp_path, job, sum(map(len, lists[:2])) + 12)
    m = history(job, prog).cut_position
    board = Board()
    r = run_job(job, GalvoDriver(HEAD), board, prog, resume=True, cut_path="continue")
    assert r.state == "done" and r.cut_choice == "continue"
    cont = board.lists[0]
    ops = [c.op for c in cont]
    assert ops.index("jump_abs_3d") < ops.index("laser_on") < ops.index("mark_abs_3d")
    path2 = [c.args for c in lists[2] if c.op == "mark_abs_3d"]
    jump = next(c for c in cont if c.op == "jump_abs_3d")
    assert jump.args == path2[m - 1]                    # from where the board stopped
    assert {"set_power", "set_frequency", "set_mark_speed"} <= set(ops)
    assert first.marks + board.marks == all_marks(job)  # every mark once, in order
    assert history(job, prog).finished


def test_continue_is_refused_where_the_board_reports_no_position(tmp_path):
    job = job_of()
    prog, _ = cut_run(tmp_path, job, 40, reports=False)
    assert history(job, prog).cut_position is None
    board = Board(reports=False)
    with pytest.raises(SafetyError, match="did not report how far path 3 got; choose remark "
                                          "or skip"):
        run_job(job, GalvoDriver(HEAD), board, prog, resume=True, cut_path="continue")
    assert board.commands == []


def test_a_path_the_board_finished_before_the_kill_is_not_marked_again(tmp_path):
    """Killed after the board finished path 1 and before "done 1" was written: the journal
    says cut; the board (after the restart) reports path 1's list complete, so continue sends
    nothing for it."""
    job = job_of(3)
    prog = progress_path_for(tmp_path / "job.json")
    run_job(job, GalvoDriver(HEAD), Board(), prog)
    jpath = prog.with_name("job.journal.jsonl")
    lines = jpath.read_text().splitlines()
    jpath.write_text("\n".join(lines[:4]) + "\n")       # begin, started 0, done 0, started 1
    restarted = Board()
    list1 = GalvoDriver(HEAD).compile(job)[1]
    restarted.pos = ListPosition(list_digest(list1), len(list1))
    with pytest.raises(SafetyError, match="the board reported 5 marks done"):
        run_job(job, GalvoDriver(HEAD), restarted, prog, resume=True)
    run_job(job, GalvoDriver(HEAD), restarted, prog, resume=True, cut_path="continue")
    assert restarted.lists == GalvoDriver(HEAD).compile(job, first_path=2)


def test_a_list_that_never_reached_the_board_is_a_cut_path_with_nothing_marked(tmp_path):
    """A fault (or an abort) between "started 2" and path 2's list: the board's last list is
    path 1's, complete — path 2 has 0 marks, and continue marks it whole, once."""
    job = job_of()
    lists = GalvoDriver(HEAD).compile(job)
    prog, first = cut_run(tmp_path, job, sum(map(len, lists[:2])))
    assert history(job, prog).cut == 2 and history(job, prog).cut_position == 0
    board = Board()
    run_job(job, GalvoDriver(HEAD), board, prog, resume=True, cut_path="continue")
    assert first.marks + board.marks == all_marks(job)


def test_killed_before_the_list_was_sent_continue_marks_the_path_once(tmp_path):
    """Killed after "started 2" was written and before its list reached the board: the board
    (after the restart) reports path 1's list complete, so path 2 is continued from its
    start."""
    job = job_of(4)
    prog = progress_path_for(tmp_path / "job.json")
    run_job(job, GalvoDriver(HEAD), Board(), prog)
    jpath = prog.with_name("job.journal.jsonl")
    lines = jpath.read_text().splitlines()
    jpath.write_text("\n".join(lines[:6]) + "\n")       # begin, 0, 0, 1, 1, started 2
    restarted = Board()
    lists = GalvoDriver(HEAD).compile(job)
    restarted.pos = ListPosition(list_digest(lists[1]), len(lists[1]))
    with pytest.raises(SafetyError, match="the board reported 0 marks done"):
        run_job(job, GalvoDriver(HEAD), restarted, prog, resume=True)
    run_job(job, GalvoDriver(HEAD), restarted, prog, resume=True, cut_path="continue")
    marks = [c.args for cmds in lists[2:] for c in cmds if c.op == "mark_abs_3d"]
    assert restarted.marks == marks


def test_resume_list():
    cmds = GalvoDriver(HEAD).compile(job_of(1))[0]
    marks = [c for c in cmds if c.op == "mark_abs_3d"]
    assert resume_list(cmds, 0) == cmds and resume_list(cmds, len(marks)) == []
    rest = resume_list(cmds, 2)
    assert [c for c in rest if c.op == "mark_abs_3d"] == marks[2:]
    assert [c.args for c in rest if c.op == "jump_abs_3d"] == [marks[1].args]


GOOD = {"format": "insitu-job-progress/1", "paths_total": 5, "completed": 2, "state": "running"}


@pytest.mark.parametrize("change, field", [
    ({"state": None}, "state"), ({"state": "paused"}, "state"),
    ({"completed": True}, "completed"), ({"completed": -1}, "completed"),
    ({"completed": 6}, "completed"), ({"completed": 2.0}, "completed"),
    ({"paths_total": "5"}, "paths_total"), ({"job_sha256": "0" * 64}, "job_sha256"),
    ({"paths_total": 7, "completed": 2}, "paths_total")])
def test_a_malformed_progress_record_is_one_line_naming_the_field(tmp_path, change, field):
    job = job_of()
    prog = progress_path_for(tmp_path / "job.json")
    rec = {**GOOD, "job_sha256": job.digest(), **change}
    prog.write_text(json.dumps({k: v for k, v in rec.items() if v is not None}))
    board = Board()
    with pytest.raises(FormatError) as e:
        run_job(job, GalvoDriver(HEAD), board, prog, resume=True)
    assert str(prog) in str(e.value) and f"{field}:" in str(e.value)
    assert "\n" not in str(e.value) and board.commands == []


@pytest.mark.parametrize("line, field", [
    ('{"event": "started", "path": true}', "path"), ('{"event": "done", "path": -1}', "path"),
    ('{"event": "done", "path": 5}', "path"), ('{"event": "fired", "path": 1}', "event"),
    ('{"event": "end", "state": "running"}', "state"), ("[1, 2]", "event")])
def test_a_malformed_journal_line_names_the_line_and_field(tmp_path, line, field):
    job = job_of()
    j = tmp_path / "job.journal.jsonl"
    begin = json.dumps({"event": "begin", "job_sha256": job.digest(), "paths_total": 5})
    j.write_text(f"{begin}\n{line}\n")
    with pytest.raises(FormatError, match=f"line 2: {field}:"):
        read_journal(j)


def test_a_journal_line_cut_short_by_a_kill_is_ignored(tmp_path):
    job = job_of()
    prog = progress_path_for(tmp_path / "job.json")
    run_job(job, GalvoDriver(HEAD), Board(), prog)
    j = tmp_path / "job.journal.jsonl"
    text = j.read_text().splitlines()
    j.write_text("\n".join(text[:3]) + '\n{"event": "sta')           # started 1 half written
    s = read_journal(j)
    assert s.done == {0} and s.cut is None and s.state == "killed"
    j.write_text("\n".join(text[:3]) + '\n{"event": "sta\n' + text[3] + "\n")
    with pytest.raises(FormatError, match="line 4: not JSON"):
        read_journal(j)


@pytest.mark.parametrize("args, message", [
    (["--cut-path", "redo", "--resume"], "--cut-path 'redo': expected one of remark, skip, "
                                         "continue"),
    (["--cut-path", "skip"], "--cut-path goes with --resume"),
    (["--resume", "--restart"], "--resume and --restart: choose one")])
def test_run_options_that_do_not_go_together(tmp_path, args, message):
    from typer.testing import CliRunner

    from insitu.cli.main import app
    job_path = tmp_path / "job.json"
    write_job(job_path, job_of())
    res = CliRunner().invoke(app, ["job", "run", str(job_path), *args])
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit)
    assert message in " ".join(res.output.split())
    assert not (tmp_path / "job.journal.jsonl").exists()


def test_job_show_prints_the_journal_summary_with_the_cut_path(tmp_path):
    from typer.testing import CliRunner

    from insitu.cli.main import app
    job = job_of()
    job_path = tmp_path / "job.json"
    write_job(job_path, job)
    lists = GalvoDriver(HEAD).compile(job)
    prog, _ = cut_run(tmp_path, job, sum(map(len, lists[:2])) + 12)
    res = CliRunner().invoke(app, ["job", "show", str(job_path)])
    text = " ".join(res.output.split())
    m = history(job, prog).cut_position
    assert res.exit_code == 0 and "interrupted: 2 of 5 paths done" in text
    assert f"cut path 3 ({m} of 5 marks done)" in text.replace("│", "").replace("  ", " ")
    assert "injected fault" in text
