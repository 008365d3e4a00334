"""``insitu record KIND --rig RIG -o REC``: record a sequence on a station (a real rig, or the
simulated one its rig file names) — the same four kinds as ``insitu sim record``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from insitu.cli.common import (
    bounded,
    check_output,
    console,
    fail,
    one_line_errors,
    parse_heights,
    progress_bar,
)
from insitu.cli.job import stop_on_signals
from insitu.cli.options import RecordCross
from insitu.services import record as svc


@one_line_errors
def record(
    kind: Annotated[str, typer.Argument(help="scan | height-calibration | field-calibration | "
                                             "camera-calibration")],
    out: Annotated[Path, typer.Option("-o", "--output",
                                      help="Folder to write (replaced if it exists).")],
    rig: Annotated[Path, typer.Option(help="Rig file of the station.")],
    spacing: Annotated[float, typer.Option(
        callback=bounded("spacing_mm"), help="Scan: line spacing, mm.")] = 0.5,
    cross: RecordCross = None,
    region: Annotated[tuple[float, float, float, float] | None, typer.Option(metavar="X0 X1 Y0 Y1", 
        callback=bounded("position_mm"),
        help="Scan: region X0 X1 Y0 Y1, mm (required on a real rig).")] = None,
    grid: Annotated[int, typer.Option(
        callback=bounded("count"), help="Field calibration: spots per side.")] = 21,
    marked: Annotated[bool, typer.Option(help="Field calibration: mark circles on the plate "
                                              "and image them instead of pilot spots.")] = False,
    heights: Annotated[str, typer.Option(metavar="Z1,Z2,...", help="Field calibration: plate "
                                         "heights, mm, comma-separated.")] = "0",
    views: Annotated[int, typer.Option(
        callback=bounded("count"), help="Camera calibration: checkerboard views (the "
                                        "operator moves the board between them).")] = 15,
) -> None:
    """Record a sequence (docs/formats.md) on the station a rig file names: a scan, the height
    calibration on the plate (Z stage), the field calibration (pilot spots or marked
    circles) or the camera calibration (checkerboard views, the operator moving the board
    when asked). The folder appears complete or not at all."""
    from insitu.services.station import connect

    if kind not in svc.KINDS:
        fail(f"KIND {kind!r}: expected one of {', '.join(svc.KINDS)}")
    plate_z = parse_heights(heights)
    if kind == "camera-calibration" and not sys.stdin.isatty():
        fail("camera-calibration: the operator moves the board between views; run it at a "
             "terminal")
    check_output(out)
    with (connect(rig) as station, stop_on_signals(f"recording {kind}", ""),
          progress_bar(f"recording {kind}") as progress):
        svc.record(station, kind, out, spacing=spacing, region=region, cross=cross,
                   grid=grid, heights=plate_z, marked=marked, next_view=_view_asker(views),
                   views=views, progress=progress)
    console.print(f"wrote {out}", highlight=False)


def _view_asker(views: int):
    """Asks the operator to bring the board into view ``i`` (None: done); view ``views`` is
    the board flat on the plate, where the head draws its axis lines."""
    def ask(i: int | None) -> None:
        if i is None:
            return
        what = (f"move the checkerboard to view {i + 1} of {views}" if i < views else
                "lay the checkerboard flat on the plate at the field centre (the head will "
                "draw its axis lines on it)")
        typer.prompt(f"{what}, then press Enter", default="", show_default=False,
                     prompt_suffix=" ")
    return ask
