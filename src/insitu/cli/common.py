"""What every command shares: one-line errors, bounded options, progress bars, output paths.

The consoles read no rich markup and no emoji codes: what they print holds user text (file
names such as ``a[/]b.json``, pattern specs such as ``qr:"x"``), printed as it is.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.text import Text

from insitu.errors import InsituError
from insitu.formats.bounds import BOUNDS

console = Console(markup=False, emoji=False)
err_console = Console(stderr=True, markup=False, emoji=False)


def tagged(tag: str, style: str, message: str) -> Text:
    """``tag`` in ``style``, then ``message`` as plain text (never read as markup)."""
    return Text.assemble((tag, style), " ", message)


def fail(message: str) -> None:
    """Print one line naming the problem and exit non-zero."""
    err_console.print(tagged("error:", "bold red", message), highlight=False, soft_wrap=True)
    raise typer.Exit(1)


def warn(message: str) -> None:
    """Print one warning line on stderr."""
    err_console.print(tagged("warning:", "yellow", message), highlight=False, soft_wrap=True)


def bounded(name: str) -> Callable:
    """A typer option ``callback``: the value (a number, a tuple of numbers, or None) must lie
    within ``insitu.formats.bounds.BOUNDS[name]``; else one line ``--option: <value> is
    outside lo … hi unit`` and exit 1, before the command starts."""
    bound = BOUNDS[name]

    def callback(param: typer.CallbackParam, value):
        for v in value if isinstance(value, (tuple, list)) else (value,):
            why = None if v is None else bound.problem(v)
            if why is not None:
                fail(f"{max(param.opts, key=len)}: {why}")
        return value
    return callback


def one_line_errors(command: Callable) -> Callable:
    """Decorate a command: an InsituError becomes one line on stderr and exit code 1."""
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except InsituError as e:
            fail(str(e))
    return wrapper


@contextlib.contextmanager
def progress_bar(description: str) -> Iterator:
    """Yields a ``progress(done, total)`` callback drawing a bar on stderr."""
    with Progress(TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
                  TimeRemainingColumn(), console=err_console, transient=True) as bar:
        task = bar.add_task(description, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def check_output(path: Path, suffix: str | None = None) -> Path:
    """The output's folder must exist; the suffix, when given, must match."""
    if not path.parent.exists():
        raise InsituError(f"{path}: folder {path.parent} does not exist")
    if suffix and path.suffix.lower() != suffix:
        raise InsituError(f"{path}: expected a {suffix} file name")
    return path


def parse_heights(text: str) -> list[float]:
    """``--heights`` "Z1,Z2,..." → distinct finite heights, mm (fails with one line)."""
    try:
        zs = [float(z) for z in text.split(",")]
    except ValueError:
        zs = []
    if not zs or not all(abs(z) < 1e3 for z in zs) or len(set(zs)) != len(zs):
        fail(f"--heights {text!r}: expected distinct plate heights in mm separated by commas, "
             "e.g. 0,20")
    return zs
