"""Shared by every tier (unit, gui, hardware): the simulated boards import as ``fakes``
(``tests/fakes``), the recordings are in ``tests/data``; under ``CliRunner`` a command that
lets an exception escape (anything but its exit) fails the test, whatever else it checks."""

import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(autouse=True)
def _commands_let_no_exception_escape(monkeypatch):
    invoke = CliRunner.invoke

    def checked(self, *args, **kwargs):
        res = invoke(self, *args, **kwargs)
        if res.exception is not None and not isinstance(res.exception, SystemExit):
            raise AssertionError(f"the command raised {type(res.exception).__name__}: "
                                 f"{res.exception}") from res.exception
        return res
    monkeypatch.setattr(CliRunner, "invoke", checked)
