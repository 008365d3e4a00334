"""The commands' output: one-line usage errors naming what an option expects; progress as
plain lines with counts when stderr is not a terminal."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from insitu.cli import common
from insitu.cli.main import USAGE_EXIT, app

runner = CliRunner()


@pytest.mark.parametrize("args, line", [
    (["mark", "--at", "0"], "error: --at: expected 2 numbers X Y"),
    (["mark", "--at", "0", "a"], "error: --at: expected 2 numbers X Y, got '0 a'"),
    (["scan", "--region", "1", "2"], "error: --region: expected 4 numbers X0 X1 Y0 Y1"),
    (["sim", "record", "--region", "1", "2", "x", "4"],
     "error: --region: expected 4 numbers X0 X1 Y0 Y1, got '1 2 x 4'"),
    (["gui", "--binning", "x"], "error: --binning: expected a whole number, got 'x'"),
    (["mark", "--bogus"], "error: No such option: --bogus (see 'insitu mark --help')"),
    (["calibrate", "nothing"], "error: No such command 'nothing'. (see 'insitu calibrate --help')"),
])
def test_usage_errors_are_one_line(args, line):
    res = runner.invoke(app, args, prog_name="insitu")
    assert res.exit_code == USAGE_EXIT
    assert res.output.strip() == line


def test_missing_option_names_it():
    res = runner.invoke(app, ["mark", "--cloud", "c.ply", "--pattern", "text:A", "--at", "1", "2"])
    assert res.exit_code == USAGE_EXIT
    assert res.output.strip() == "error: --output: missing; expected a file name"


def test_help_metavars_show_the_words():
    out = runner.invoke(app, ["scan", "--help"], terminal_width=200).output
    assert "X0 X1 Y0 Y1" in out and "float,float" not in out
    assert "X Y" in runner.invoke(app, ["mark", "--help"], terminal_width=200).output


def test_no_args_still_shows_help():
    res = runner.invoke(app, ["calibrate"])
    assert "Usage:" in res.output and "error:" not in res.output


def test_progress_without_terminal_prints_counted_lines(monkeypatch, capsys):
    monkeypatch.setattr(common, "err_console", common.Console(stderr=True, force_terminal=False))
    clock = iter(range(1000))
    monkeypatch.setattr(common.time, "monotonic", lambda: next(clock) * 0.001)
    with common.progress_bar("marking", "paths") as progress:
        for done in range(1, 814):
            progress(done, 813)
    lines = capsys.readouterr().err.splitlines()
    assert lines[-1] == "marking: 813 of 813 paths"
    assert lines[0] == "marking: 82 of 813 paths"    # 10 % of the work, well before 2 s
    assert 9 <= len(lines) <= 11


def test_progress_without_terminal_prints_every_two_seconds(monkeypatch, capsys):
    monkeypatch.setattr(common, "err_console", common.Console(stderr=True, force_terminal=False))
    clock = iter(range(1000))
    monkeypatch.setattr(common.time, "monotonic", lambda: next(clock) * 1.0)   # 1 s per call
    with common.progress_bar("scanning") as progress:
        for done in range(1, 6):
            progress(done, 1000)
    assert capsys.readouterr().err.splitlines() == ["scanning: 2 of 1000", "scanning: 4 of 1000",
                                                   "scanning: 5 of 1000"]


def test_progress_at_a_terminal_draws_the_bar(monkeypatch, capsys):
    monkeypatch.setattr(common, "err_console", common.Console(stderr=True, force_terminal=True))
    with common.progress_bar("marking", "paths") as progress:
        progress(5, 10)
    err = capsys.readouterr().err
    assert "marking" in err and "5 of 10" not in err and "5/10" in err
