"""insitu: in-situ structured-light measurement and laser marking (headless commands)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer
import typer.core

from insitu.cli import calibrate as calibrate_cmd
from insitu.cli import camera as camera_cmd
from insitu.cli import centres as centres_cmd
from insitu.cli import depth as depth_cmd
from insitu.cli import engrave as engrave_cmd
from insitu.cli import field as field_cmd
from insitu.cli import inspect as inspect_cmd
from insitu.cli import job as job_cmd
from insitu.cli import locate as locate_cmd
from insitu.cli import mark as mark_cmd
from insitu.cli import pattern as pattern_cmd
from insitu.cli import produce as produce_cmd
from insitu.cli import recipe as recipe_cmd
from insitu.cli import record as record_cmd
from insitu.cli import scan as scan_cmd
from insitu.cli import serial as serial_cmd
from insitu.cli import sim as sim_cmd
from insitu.cli.common import USAGE_EXIT, OneLineUsage, bounded, err_console, fail, tagged
from insitu.formats.project import SIM_BINNING

__all__ = ["USAGE_EXIT", "app", "main"]
GUI_MODULES = ("PySide6", "OpenGL")      # the packages of the ``gui`` extra, as imported
app = typer.Typer(cls=OneLineUsage, help=__doc__.split("\n")[0] if __doc__ else None,
                  no_args_is_help=True, pretty_exceptions_enable=False, add_completion=False,
                  rich_markup_mode="markdown")
app.command("scan")(scan_cmd.scan)
app.command("mark")(mark_cmd.mark)
app.command("inspect")(inspect_cmd.inspect)
app.command("locate")(locate_cmd.locate)
app.command("record")(record_cmd.record)
app.command("centres")(centres_cmd.centres)
app.command("engrave")(engrave_cmd.engrave)
app.command("depth")(depth_cmd.depth)
calibrate_cmd.app.command("camera")(camera_cmd.camera)
calibrate_cmd.app.command("field")(field_cmd.field)
app.add_typer(calibrate_cmd.app, name="calibrate")
galvo_app = typer.Typer(help="The scan head: field correction of commands, and its drift check.",
                        no_args_is_help=True, rich_markup_mode="markdown")
galvo_app.command("correct")(field_cmd.correct)
galvo_app.command("check")(field_cmd.check)
app.add_typer(galvo_app, name="galvo")
app.add_typer(job_cmd.app, name="job")
app.add_typer(pattern_cmd.app, name="pattern")
app.add_typer(serial_cmd.app, name="serial")
app.add_typer(recipe_cmd.app, name="recipe")
app.command("produce")(produce_cmd.produce)
app.add_typer(sim_cmd.app, name="sim")


@app.command("gui")
def gui(
    project: Annotated[Path | None, typer.Argument(help="Project file to open "
                                                        "(.insitu.json).")] = None,
    rig: Annotated[Path | None, typer.Option(help="Rig file (default: the simulated rig).")] = None,
    workpiece: Annotated[str, typer.Option(
        help="Simulated rig: the part on the table.")] = "step-block",
    binning: Annotated[int, typer.Option(
        help="Simulated rig: divide the image size by this.",
        callback=bounded("binning"))] = SIM_BINNING,
) -> None:
    """Open the operator's application: connect the rig, scan, place patterns on the cloud,
    preview and mark, calibrate; projects save the whole session."""
    if project is not None and not project.is_file():
        fail(f"{project}: project file not found")
    try:
        from insitu.ui.qt.app import run  # Qt is imported only for this command
    except ImportError as e:
        missing = (e.name or "").split(".")[0]
        if isinstance(e, ModuleNotFoundError) and missing in GUI_MODULES:
            fail(f"the GUI needs PySide6 and PyOpenGL ({missing} is not installed): "
                 + "pip install 'insitu[gui]'")
        fail(f"the GUI cannot start: {e} (Qt/OpenGL libraries missing? see scripts/setup.sh)")
    raise typer.Exit(run(project, rig, workpiece, binning))


def main() -> None:
    try:
        app()
    except KeyboardInterrupt:
        err_console.print(tagged("error:", "bold red", "interrupted"))
        sys.exit(130)
