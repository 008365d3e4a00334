"""What every command shares: one-line errors, progress bars, output paths."""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from insitu.errors import InsituError

console = Console()
err_console = Console(stderr=True)


def fail(message: str) -> None:
    """Print one line naming the problem and exit non-zero."""
    err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    raise typer.Exit(1)


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
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
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
