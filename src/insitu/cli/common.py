"""What every command shares: one-line errors, bounded options, progress bars, output paths.

The consoles read no rich markup and no emoji codes: what they print holds user text (file
names such as ``a[/]b.json``, pattern specs such as ``qr:"x"``), printed as it is.
"""

from __future__ import annotations

import contextlib
import enum
import functools
import time
import typing
from collections.abc import Callable, Iterator
from pathlib import Path

import typer
import typer.core
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.text import Text
from typer._click import exceptions as usage  # typer vendors click: its errors, not click's

from insitu.errors import InsituError
from insitu.formats.bounds import BOUNDS

console = Console(markup=False, emoji=False, soft_wrap=True)
err_console = Console(stderr=True, markup=False, emoji=False, soft_wrap=True)


def tagged(tag: str, style: str, message: str) -> Text:
    """``tag`` in ``style``, then ``message`` as plain text (never read as markup)."""
    return Text.assemble((tag, style), " ", message)


def fail(message: str) -> None:
    """Print one line naming the problem and exit non-zero."""
    err_console.print(tagged("error:", "bold red", message), highlight=False)
    raise typer.Exit(1)


def missing(message: str) -> None:
    """A required option not given, found by the command (options required only without
    another): one line, exit 2 as click's own usage errors."""
    err_console.print(tagged("error:", "bold red", message), highlight=False)
    raise typer.Exit(2)


def warn(message: str) -> None:
    """Print one warning line on stderr."""
    err_console.print(tagged("warning:", "yellow", message), highlight=False)


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


def bounded_each(*names: str) -> Callable:
    """A typer option ``callback`` for a tuple: its i-th number within ``BOUNDS[names[i]]``."""
    checks = [bounded(n) for n in names]

    def callback(param: typer.CallbackParam, value):
        for check, v in zip(checks, value or ()):
            check(param, v)
        return value
    return callback


def one_line_errors(command: Callable) -> Callable:
    """Decorate a command: an InsituError becomes one line on stderr and exit code 1."""
    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except InsituError as e:
            for line in e.warnings:
                warn(line)
            fail(as_option(e))
    return wrapper


def as_option(e: InsituError) -> str:
    """The error's line with the field it names shown as this command's option
    (``cut path 'x': …`` → ``--cut-path 'x': …``)."""
    text = str(e)
    words = (e.field or "").replace("_", " ")
    if words and text.startswith(words):
        return "--" + e.field.replace("_", "-") + text[len(words):]
    return text


PLAIN_EVERY_S = 2.0       # without a terminal: a progress line at most this often …
PLAIN_EVERY_FRACTION = 0.1  # … or when this much more of the work is done


@contextlib.contextmanager
def progress_bar(description: str, unit: str = "") -> Iterator:
    """Yields a ``progress(done, total)`` callback: a live bar on stderr at a terminal; else
    (a pipe, a log, a test) plain lines ``description: done of total unit`` every
    ``PLAIN_EVERY_S`` or ``PLAIN_EVERY_FRACTION`` of the work, and the final count."""
    if not err_console.is_terminal:
        with _plain_progress(description, unit) as update:
            yield update
        return
    with Progress(TextColumn("{task.description}", markup=False), BarColumn(), MofNCompleteColumn(),
                  TimeRemainingColumn(), console=err_console, transient=True) as bar:
        task = bar.add_task(description, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


@contextlib.contextmanager
def _plain_progress(description: str, unit: str) -> Iterator:
    """The ``progress(done, total)`` callback of ``progress_bar`` without a terminal."""
    last = {"t": time.monotonic(), "done": 0, "shown": -1, "total": 0}

    def line(done: int, total: int) -> None:
        text = f"{description}: {done} of {total}" + (f" {unit}" if unit else "")
        err_console.print(text, highlight=False)
        last.update(t=time.monotonic(), shown=done)

    def update(done: int, total: int) -> None:
        last.update(done=done, total=total)
        step = PLAIN_EVERY_FRACTION * total
        if done != last["shown"] and (time.monotonic() - last["t"] >= PLAIN_EVERY_S
                                      or (total > 0 and done - max(last["shown"], 0) >= step)):
            line(done, total)

    yield update
    if last["done"] and last["done"] != last["shown"]:
        line(last["done"], last["total"])


ARGS_KEY = "insitu.args"    # click context meta: the command line's words, for usage_line


def usage_line(e: usage.UsageError, command=None, path: str = "insitu") -> str:
    """One line for a command-line mistake click found: the option and what it expects
    (``--at: expected 2 numbers X Y, got '0 a'``), or click's own message on one line.
    ``command``/``path``: the command the words were for, when the error names no context."""
    param = getattr(e, "param", None)
    if isinstance(e, usage.BadParameter) and param is not None and param.opts[0].startswith("-"):
        name = max(param.opts, key=len)
        if isinstance(e, usage.MissingParameter):
            return f"{name}: missing; expected {_expected(param)}"
        given = _given(e.ctx.meta.get(ARGS_KEY, ()) if e.ctx else (), param)
        return f"{name}: expected {_expected(param)}" + (f", got {given!r}" if given else "")
    option = getattr(e, "option_name", None)
    command = e.ctx.command if e.ctx else command
    if isinstance(e, usage.BadOptionUsage) and not isinstance(e, usage.NoSuchOption) and command:
        found = [p for p in command.params if option in p.opts]
        if found:
            return f"{option}: expected {_expected(found[0])}"
    message = " ".join(e.format_message().split())
    where = e.ctx.command_path if e.ctx else path
    return f"{message} (see '{where} --help')"


def _expected(param) -> str:
    """What a typer option takes, in words: ``2 numbers X Y``, ``one of a, b``, ``a number``."""
    kinds = {float: "number", int: "whole number", Path: "file name", str: "word"}
    annotation = param.type_descriptor.annotation
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    if typing.get_origin(annotation) is typing.Literal:
        return "one of " + ", ".join(map(str, args))
    if isinstance(annotation, type) and issubclass(annotation, enum.Enum):
        return "one of " + ", ".join(str(m.value) for m in annotation)
    inner = args[0] if args else annotation
    if typing.get_origin(inner) is tuple:       # ``tuple[float, float] | None``
        inner = typing.get_args(inner)[0]
    kind = kinds.get(inner, "value")
    if param.nargs > 1:
        return f"{param.nargs} {kind}s {param.metavar or ''}".rstrip()
    return f"a {kind}"


def _given(args: list[str], param) -> str | None:
    """The words typed after the option (as many as it takes), or None."""
    for i, word in enumerate(args):
        if word in param.opts:
            return " ".join(args[i + 1:i + 1 + param.nargs])
        if any(word.startswith(opt + "=") for opt in param.opts):
            return word.split("=", 1)[1]
    return None


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


USAGE_EXIT = 2                            # a command-line mistake exits 2, as click's do


class OneLineUsage(typer.core.TyperGroup):
    """The root group: a mistake in any command's options or arguments is one line on stderr
    naming the option and what it expects, and exit code ``USAGE_EXIT``."""

    def invoke(self, ctx: typer.Context):
        words = [*getattr(ctx, "_protected_args", ()), *ctx.args]   # the command's name first
        ctx.meta[ARGS_KEY] = words
        try:
            return super().invoke(ctx)
        except usage.NoArgsIsHelpError:
            raise
        except usage.UsageError as e:
            command, path = self, ctx.command_path
            for word in words:                    # the (sub)command the words were for
                sub = getattr(command, "commands", {}).get(word)
                if sub is None:
                    break
                command, path = sub, f"{path} {word}"
            err_console.print(tagged("error:", "bold red", usage_line(e, command, path)),
                              highlight=False)
            raise typer.Exit(USAGE_EXIT) from None
