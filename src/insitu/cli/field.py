"""``insitu calibrate field``, ``insitu galvo correct`` and ``insitu galvo check``: the
scan-field correction, applied to targets and checked for drift.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table

from insitu.calibrate.field_file import FIELD_METHODS
from insitu.cli.common import (
    bounded,
    check_output,
    console,
    fail,
    one_line_errors,
    progress_bar,
    warn,
)
from insitu.formats.validation import one_of


@one_line_errors
def field(
    rec: Annotated[Path, typer.Argument(metavar="REC", help="Recorded field-calibration "
                                                           "folder (spots on the plate).")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Field correction file (.json); "
                                      "the report is written beside it (.png).")],
    method: Annotated[str, typer.Option(help="; ".join(f"{k}: {m.description}" for k, m in
                                                       FIELD_METHODS.items()) + ".")] = "rbf",
    sigma: Annotated[float | None, typer.Option(
        callback=bounded("rbf_sigma_mm"),
        help="RBF spread σ, mm (default: chosen by 5-fold CV over 0.15…0.75 × the half "
             "field).")] = None,
    mse_goal: Annotated[float | None, typer.Option(
        callback=bounded("mse_goal_mm2"),
        help="RBF MSE goal, mm² (default: chosen by 5-fold CV over 1e-5…1e-3).")] = None,
    smoothing: Annotated[float | None, typer.Option(
        callback=bounded("smoothing"),
        help="Table smoothing (default: chosen by 5-fold CV over 1e-4…1).")] = None,
) -> None:
    """Fit a scan-field correction from a recorded field calibration: find each spot, intersect
    its camera ray with the plate, model the deviations (spread / MSE goal or smoothing by
    5-fold cross-validation), and write FIELD.json and the quiver report FIELD.png."""
    from insitu.calibrate.report import format_area_rows
    from insitu.services.field import calibrate_and_report

    check_output(out, ".json")
    if method not in FIELD_METHODS:
        fail(f"--method {method!r}: expected {one_of(FIELD_METHODS)}")
    options = {k: [v] for k, v in (("sigmas", sigma), ("goals", mse_goal),
                                   ("smoothing", smoothing)) if v is not None}
    with progress_bar("field calibration") as progress:
        cal = calibrate_and_report(rec, out, method, progress, **options)
    r = cal.residuals
    table = Table(title=f"field correction → {out}, {out.with_suffix('.png').name}",
                  show_header=False)
    table.add_row("recording", cal.notes)
    table.add_row("before, |δ| mm", f"RMS {r['before_rms_mm']:.4f}  max {r['before_max_mm']:.4f}")
    table.add_row("fit residual, mm", f"RMS {r['fit_rms_mm']:.4f}  max {r['fit_max_mm']:.4f}")
    table.add_row("after (5-fold CV), mm",
                  f"RMS {r['cv_rms_mm']:.4f}  max {r['cv_max_mm']:.4f}  (fold RMS "
                  f"{r['cv_fold_rms_mean_mm']:.4f} ± {r['cv_fold_rms_std_mm']:.4f})")
    console.print(table)
    console.print("\n".join(format_area_rows(cal.areas_before, cal.areas_after)),
                  highlight=False)


@one_line_errors
def correct(
    field_file: Annotated[Path, typer.Argument(metavar="FIELD.json",
                                               help="Field correction file.")],
    targets: Annotated[Path, typer.Argument(
        metavar="TARGETS.csv",
        help="Where the spot must land: UTF-8 text, the header line x,y, then one target per "
             "line: x,y in mm on the focal plane z = 0, scan-head frame (origin at the field "
             "centre), e.g. 0,0 and -40.5,12.25.")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Corrected commands (.csv).")],
) -> None:
    """Corrected commands for targets: COMMANDS.csv (header x,y, same order) holds, for each
    target, the command K with K + δ(K) = target, so that the spot lands on the target.

    TARGETS.csv is plain text: the header `x,y`, then one target per line, x and y in mm on
    the nominal focal plane z = 0 in the scan-head frame (origin at the field centre, x the
    direction the scan lines are offset along), comma-separated, `.` as the decimal point;
    blank lines are skipped, every target must lie inside the scan field. For example
    `x,y` / `0,0` / `-40.5,12.25` / `60,-60`, one per line."""
    from insitu.calibrate.field_file import load_field_correction
    from insitu.services.field import correct_targets, read_targets_csv, write_commands_csv

    check_output(out, ".csv")
    cal = load_field_correction(field_file)
    Q = read_targets_csv(targets)
    K = correct_targets(cal, Q, where=f"{targets}: target")
    write_commands_csv(out, K)
    outside = cal.outside_region(Q)
    if outside.any():
        x0, x1, y0, y1 = cal.region_mm
        warn(f"{int(outside.sum())} of {len(Q)} targets lie outside the calibrated region "
             f"x {x0:g}…{x1:g}, y {y0:g}…{y1:g} mm: their correction is extrapolated")
    shift = (K - Q)
    console.print(f"wrote {out}: {len(K)} commands (correction up to "
                  f"{float(abs(shift).max()) if len(K) else 0.0:.3f} mm)", highlight=False)


@one_line_errors
def check(
    field_file: Annotated[Path, typer.Argument(metavar="FIELD.json",
                                               help="Field correction file.")],
    rec: Annotated[Path, typer.Argument(metavar="REC", help="Recorded field-calibration folder: "
                                        "a few spots on the plate, raw or corrected commands.")],
    tolerance: Annotated[float | None, typer.Option(
        callback=bounded("tolerance_mm"),
        help="Largest landing error allowed, mm (default: 3 × the correction's CV RMS, at "
             "least 0.03 mm).")] = None,
) -> None:
    """Check that a field correction still holds (drift): measure where the recorded spots
    landed and compare with where FIELD.json predicts they land. Prints every point; exits 0
    if all are within the tolerance, 1 with a line naming the worst point if not."""
    from insitu.calibrate.field_file import load_field_correction
    from insitu.services.field import check_drift

    cal = load_field_correction(field_file)
    with progress_bar("drift check", "points") as progress:
        d = check_drift(cal, rec, tolerance_mm=tolerance, progress=progress)
    err = np.linalg.norm(d.residuals, axis=1)
    table = Table(title=f"{rec} against {field_file}: landing points, mm")
    for c in ("#", "command x, y", "predicted x, y", "measured x, y", "error"):
        table.add_column(c, justify="right")
    for k, (c, p, m, e) in enumerate(zip(d.commands, d.predicted, d.measured, err), start=1):
        style = "red" if e > d.tolerance_mm else None
        table.add_row(str(k), *(f"{a[0]:.3f}, {a[1]:.3f}" for a in (c, p, m)), f"{e:.4f}",
                      style=style)
    console.print(table)
    worst = int(np.argmax(err))
    if not d.holds:
        c = d.commands[worst]
        fail(f"{field_file} no longer holds: point {worst + 1} (command [{c[0]:g}, {c[1]:g}] mm) "
             f"landed {err[worst]:.3f} mm from its prediction, over the tolerance of "
             f"{d.tolerance_mm:.3f} mm (RMS {d.rms_mm:.3f} mm over {len(err)} points); "
             "recalibrate the field")
    console.print(f"{field_file} holds: RMS {d.rms_mm:.4f} mm, max {d.max_mm:.4f} mm (point "
                  f"{worst + 1}), tolerance {d.tolerance_mm:.4f} mm, {len(err)} points",
                  highlight=False)
