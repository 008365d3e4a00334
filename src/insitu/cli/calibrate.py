"""``insitu calibrate …``: calibrations from recorded sequences."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from insitu.cli.common import check_output, console, one_line_errors, progress_bar

app = typer.Typer(help="Calibrations from recorded sequences.", no_args_is_help=True,
                 rich_markup_mode="markdown")


@app.command("height")
@one_line_errors
def height_cmd(
    hcal: Annotated[Path, typer.Argument(help="Recorded height-calibration folder.")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Height calibration file (.json); "
                                      "the residual grid is drawn beside it (.png).")],
) -> None:
    """Fit the height calibration (Li et al. §2.2, and ours, the default; ours also for the
    crossed lines when the recording has them, for scans with --cross) and write it with its
    residuals, per plate height and line offset, and their picture."""
    from insitu.services.height import calibrate_height_and_report

    check_output(out, ".json")
    with progress_bar("height calibration") as progress:
        cal = calibrate_height_and_report(hcal, out, progress)
    table = Table(title=f"height calibration → {out}, {out.with_suffix('.png').name}",
                  show_header=False)
    table.add_row("recording", cal.notes)
    table.add_row("default model", cal.model)
    for key, value in cal.residuals.items():
        table.add_row(key, f"{value:.4f}" if key.endswith("_mm") else f"{value:,.0f}")
    console.print(table)
