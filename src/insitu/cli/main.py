"""insitu: in-situ structured-light measurement and laser marking (headless commands)."""

from __future__ import annotations

import sys

import typer

from insitu.cli import calibrate as calibrate_cmd
from insitu.cli import camera as camera_cmd
from insitu.cli import field as field_cmd
from insitu.cli import mark as mark_cmd
from insitu.cli import scan as scan_cmd
from insitu.cli import sim as sim_cmd
from insitu.cli.common import err_console

app = typer.Typer(help=__doc__.split("\n")[0] if __doc__ else None, no_args_is_help=True,
                  pretty_exceptions_enable=False, add_completion=False,
                  rich_markup_mode="markdown")
app.command("scan")(scan_cmd.scan)
app.command("mark")(mark_cmd.mark)
calibrate_cmd.app.command("camera")(camera_cmd.camera)
calibrate_cmd.app.command("field")(field_cmd.field)
app.add_typer(calibrate_cmd.app, name="calibrate")
galvo_app = typer.Typer(help="The scan head: field correction of commands.", no_args_is_help=True,
                        rich_markup_mode="markdown")
galvo_app.command("correct")(field_cmd.correct)
app.add_typer(galvo_app, name="galvo")
app.add_typer(sim_cmd.app, name="sim")


def main() -> None:
    try:
        app()
    except KeyboardInterrupt:
        err_console.print("[bold red]error:[/] interrupted")
        sys.exit(130)
