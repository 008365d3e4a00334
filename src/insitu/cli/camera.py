"""``insitu calibrate camera REC -o CAMERA.json``; ``insitu calibrate camera FOLDER --board
COLSxROWSxSQUARE_MM -o CAMERA.json`` for a plain folder of board photos.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from insitu.cli.common import check_output, console, one_line_errors, progress_bar


@one_line_errors
def camera(
    rec: Annotated[Path, typer.Argument(help="Recorded camera-calibration folder (checkerboard "
                                             "views, optionally the head's axis lines on the "
                                             "board), or a folder of spots on the plate at two "
                                             "heights (re-estimates the pose only), or a "
                                             "plain folder of board photos (with --board).")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Camera calibration file (.json); "
                                      "its picture is drawn beside it (.png).")],
    intrinsics: Annotated[Path | None, typer.Option(
        help="Spots only: camera calibration whose intrinsics to keep (default: the "
             "sequence's camera).")] = None,
    scan_head: Annotated[Path | None, typer.Option(
        "--scan-head", help="Spots only: scan-head config (nominal mirror distance and "
                            "separation).")] = None,
    field: Annotated[Path | None, typer.Option(
        help="Spots only: field correction describing where uncorrected commands land.")] = None,
    board: Annotated[str | None, typer.Option(
        help="The board as COLSxROWSxSQUARE_MM (inner corners across, down, square side in "
             "mm; e.g. 9x6x25). Needed for a folder of photos without sequence.json (every "
             ".png/.jpg/.jpeg/.bmp/.tif, by name); with a sequence.json it must agree with the "
             "recorded checkerboard.")] = None,
    charuco: Annotated[str | None, typer.Option(
        help="With --board: a ChArUco board, its ArUco dictionary and marker side, "
             "DICT[:MARKER_MM] (e.g. DICT_4X4_50:7).")] = None,
) -> None:
    """Calibrate the camera: intrinsics and distortion from the checkerboard views (bad views
    rejected and listed), with their uncertainties, and its pose in the scan-head frame from
    the head's x and y axis lines drawn on the board lying on the plate. Given spots on the
    plate at two heights instead, re-estimate only the pose (after the camera moved). The
    picture beside the file shows the reprojection RMS of each view."""
    from insitu.calibrate.photos import parse_board
    from insitu.errors import CalibrationError
    from insitu.services.camera import calibrate_camera_and_report

    check_output(out, ".json")
    if charuco is not None and board is None:
        raise CalibrationError("--charuco: give the board's size too (--board COLSxROWSxSQUARE_MM)")
    spec = parse_board(board, charuco) if board is not None else None
    with progress_bar("camera calibration") as progress:
        cal = calibrate_camera_and_report(rec, out, intrinsics, scan_head, field, progress, spec)
    K = cal.camera.K
    table = Table(title=f"camera calibration → {out}, {out.with_suffix('.png').name}",
                  show_header=False)
    table.add_row("recording", cal.notes)
    table.add_row("fx, fy, cx, cy (px)",
                  f"{K[0][0]:.2f}  {K[1][1]:.2f}  {K[0][2]:.2f}  {K[1][2]:.2f}")
    if cal.std_intrinsics:
        table.add_row("± 1σ (px)", "  ".join(f"{s:.3f}" for s in cal.std_intrinsics[:4]))
    table.add_row("dist k1 k2 p1 p2 k3", "  ".join(f"{d:.5f}" for d in cal.camera.dist))
    for key, value in cal.residuals.items():
        table.add_row(key, f"{value:g}" if key in ("views_used", "views_rejected", "spots")
                      else f"{value:.4f}")
    console.print(table)
