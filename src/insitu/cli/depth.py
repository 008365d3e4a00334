"""``insitu depth``: the depth of pockets measured on a recorded scan."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import typer
from rich.table import Table

from insitu.cli.common import bounded, console, fail, one_line_errors, progress_bar, warn
from insitu.cli.options import HeightCal, HeightModel, Method, scan_calibration

Scan = Annotated[Path, typer.Argument(
    metavar="SCAN", help="A recorded scan folder (replayed with the depth scan's line "
                         "centres: across the line only), or a measured cloud (.ply) that "
                         "keeps each point's line.")]
Pockets = Annotated[list[str] | None, typer.Option(
    "--pocket", metavar="X0,Y0,X1,Y1",
    help="A pocket's box, mm, world frame, or its outline's corners X1,Y1,X2,Y2,X3,Y3,… (a "
         "turned pocket; again for more pockets). Without any: the "
         "pockets are found — regions of ≥ 0.5 mm² below the scan's top by more than 3 × "
         "its noise, each outlined where the depth crosses half the pocket's (a rectangle, "
         "turned as it lies, where it is one).")]
Tolerance = Annotated[float, typer.Option(
    callback=bounded("depth_mm"),
    help="A depth is stated when its 2σ is within this, mm.")]
Passes = Annotated[Literal["both", "1", "2"], typer.Option(
    "--pass",
    help="A crossed scan (recorded with --cross: two passes of parallel lines): both — each "
         "pocket measured from each pass on its own, their depths combined by their inverse "
         "variances, of the passes crossing its walls as squarely as the best one (within "
         "10°; a pass slanted to them, e.g. at 45° to a square pocket's walls, reported, not "
         "combined; a pocket one pass cannot measure from the other alone; each said); 1 — from "
         "the first pass recorded alone; 2 — from the crossed one alone. A scan of one pass: "
         "both and 1 alike.")]
Report = Annotated[Path | None, typer.Option(
    "-o", "--output", metavar="REPORT_DIR",
    help="Also write a report folder (replaced as a whole): depth.json and each measured "
         "pocket's depth map (pocket-K.png).")]


@one_line_errors
def depth(scan: Scan, pocket: Pockets = None, height_cal: HeightCal = None,
          method: Method = None, height_model: HeightModel = None,
          tolerance: Tolerance = 0.005, which: Passes = "both", out: Report = None) -> None:
    """Measure each pocket's depth on a scan: its floor against the top around it, from the
    same scan lines; without --pocket, on the pockets it finds. A depth is stated when 2σ is
    within the tolerance and its floor holds the 8 lines clear of its walls a statement needs
    (lines ≤ 0.1 mm apart across a 2 mm pocket); from fewer lines (at least 2) it is given
    with its σ, not stated, and one line naming the spacing that would. A pocket that cannot
    be measured gets one line saying why and what to do; the others are still measured.
    Exit 1 when none is. A crossed scan: each pocket from each pass, their depths combined
    (--pass); its pockets found on its first pass."""
    from insitu.errors import MeasurementError
    from insitu.services.depth import (
        finding_points,
        load_depth_scan,
        measure_pockets,
        plane_scale_warning,
    )
    from insitu.services.depth_find import find_pockets
    from insitu.services.depth_report import write_report

    regions = [_region(p) for p in pocket or ()]
    if out is not None and not out.parent.is_dir():
        fail(f"-o {out}: folder {out.parent} does not exist")
    cal = scan_calibration(method, height_cal, height_model)
    with progress_bar("replaying", "frames") as progress:
        data = load_depth_scan(scan, cal, height_model, progress)
    try:
        if not regions:
            regions = find_pockets(*finding_points(data, which))
            if not regions:
                fail(f"{scan}: no pocket found (no region of 0.5 mm² below the top by more "
                     "than 3 × its noise): give the pockets with --pocket X0,Y0,X1,Y1")
        results = measure_pockets(data, regions, tolerance, which=which)
    except MeasurementError as e:
        fail(f"{scan}: {e}")
    if cal is None and scan.is_dir():
        warn(plane_scale_warning(regions))
    console.print(_table(results, scan, data, tolerance, found=not pocket))
    for p in results:
        if p.refused is not None:
            warn(f"pocket {p.name}: not measured: {p.refused}")
            continue
        for line in (p.note, p.off_floor):
            if line is not None:
                warn(f"pocket {p.name}: {line}")
    if out is not None:
        write_report(out, results, tolerance, str(scan), data.method)
        console.print(f"report → {out}", highlight=False)
    if all(p.map is None for p in results):
        fail("no pocket measured")


def _region(text: str):
    """"x0,y0,x1,y1" (mm): the box; "x1,y1,x2,y2,x3,y3,…": the polygon of those corners;
    checked."""
    import shapely

    try:
        v = [float(t) for t in text.replace(" ", ",").split(",") if t]
    except ValueError:
        v = []
    if len(v) == 4:
        if not (v[0] < v[2] and v[1] < v[3]):
            fail(f"--pocket {text!r}: expected X0 < X1 and Y0 < Y1")
        return shapely.box(*v)
    poly = shapely.Polygon(np.reshape(v, (-1, 2))) if len(v) >= 6 and len(v) % 2 == 0 else None
    if poly is None or not poly.is_valid or poly.area <= 0:
        fail(f"--pocket {text!r}: expected X0,Y0,X1,Y1 (a box) or the corners of a simple "
             "outline X1,Y1,X2,Y2,X3,Y3,… (mm)")
    return poly


def _table(results, scan: Path, data, tolerance: float, found: bool) -> Table:
    """A row per pocket; on a crossed scan a row per pass under it, and the pocket's own row
    the passes' depths combined."""
    from insitu.services.depth import FEW_LINES
    from insitu.services.depth_find import describe

    crossed = any(p.passes for p in results)
    table = Table(title=f"depth → {scan} ({data.method}; stated: 2σ within "
                        f"±{tolerance * 1e3:g} µm)")
    for col in ("pocket, mm", *(("found",) if found else ()), *(("pass",) if crossed else ()),
                "depth mm", "±1σ µm", "stated", "floor lines", "points"):
        table.add_column(col, justify="right")
    for p in results:
        head = (p.name, describe(p.region)) if found else (p.name,)
        if crossed:
            used = [q for q in p.passes if q.map is not None and q.combined]
            head += ("both" if len(used) > 1 else
                     f"{used[0].line_pass.number} alone" if used else "—",)
        if p.map is None:
            table.add_row(*head, "—", "—", "not measured", "—", "—")
        else:
            few = p.note is not None and FEW_LINES in p.note
            table.add_row(*head, f"{p.mean_mm:.4f}", f"{p.sem_mm * 1e3:.1f}",
                          "yes" if p.stated else "no, few lines" if few else "no",
                          str(p.floor_lines), f"{p.floor_points:,}")
        for q in p.passes:
            under = ("", "") if found else ("",)
            what = f"{q.line_pass.number} ({round(q.line_pass.angle_deg) % 180}°)"
            if q.map is None:
                table.add_row(*under, what, "—", "—", "not measured", "—", "—")
            else:
                table.add_row(*under, what, f"{q.mean_mm:.4f}", f"{q.sem_mm * 1e3:.1f}",
                              "not combined" if not q.combined else
                              "few lines" if q.note else "", str(q.map.floor_lines),
                              f"{len(q.map.floor):,}")
    if data.viewpoints is None:
        table.caption = "the cloud names no camera: cells a wall hides are not told apart"
    return table
