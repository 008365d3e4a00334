"""``insitu serial``: show or set the serial counter that ``{serial}`` in a pattern takes from."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from insitu.cli.common import console, one_line_errors

app = typer.Typer(help="The serial counter of variable data ({serial} in a pattern's text).",
                  no_args_is_help=True, rich_markup_mode="markdown")
CounterArg = Annotated[Path, typer.Argument(metavar="COUNTER.json",
                                            help="Serial counter (default: the one of jobs "
                                                 "written in this folder).")]


@app.command("show")
@one_line_errors
def show(counter: CounterArg = Path("serial.counter.json")) -> None:
    """The next serial and the last ones issued, with their jobs."""
    from insitu.formats.counter import read_counter

    c = read_counter(counter)
    table = Table(title=str(counter), show_header=False)
    table.add_row("next", str(c.next))
    for i in reversed(c.issued):
        table.add_row(f"issued {i.serial}", f"{i.time}  {i.job or '-'}"
                      + (f"  {i.digest[:12]}" if i.digest else ""))
    console.print(table)


@app.command("set")
@one_line_errors
def set_next(
    counter: Annotated[Path, typer.Argument(metavar="COUNTER.json", help="Serial counter "
                                                                         "(created if missing).")],
    next_serial: Annotated[int, typer.Argument(metavar="NEXT", help="The serial the next job "
                                                                    "takes.")],
    force: Annotated[bool, typer.Option(help="Allow a serial that was issued already (it would "
                                             "be marked twice).")] = False,
) -> None:
    """Make NEXT the serial the next job takes. A serial at or below one already issued is
    refused without --force: it would mark two parts alike."""
    from insitu.formats.counter import locked

    with locked(counter) as c:
        before = c.counter.next if c.counter is not None else None
        c.set_next(next_serial, force)
    console.print(f"{counter}: next serial {next_serial}"
                  + (f" (was {before})" if before is not None else " (new counter)"),
                  highlight=False)
