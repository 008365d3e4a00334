"""``insitu mark``: place a pattern on a measured cloud, write the mark job, optionally mark it."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from insitu.cli.common import check_output, console, fail, one_line_errors, progress_bar
from insitu.cli.job import (CutPath, Field, Inspect, Preview, Restart, Resume, Rig, Seed,
                            Workpiece, check_run_options, run_on_station)
from insitu.marking.modes import PROJECTIONS, projection_mode
from insitu.patterns.dxf import FILL_MODES
from insitu.patterns.load import sources_help
from insitu.patterns.vector import BEAM_MM


@one_line_errors
def mark(
    cloud: Annotated[Path, typer.Option(help="Measured point cloud (.ply) of the part.")],
    pattern: Annotated[str, typer.Option(help=f"A file or spec: {sources_help()}.")],
    at: Annotated[tuple[float, float], typer.Option(help="Centre of the pattern X Y, mm, "
                                                         "world frame.")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Mark job to write (.json).")],
    width: Annotated[float | None, typer.Option(
        help="Width of the pattern, mm (before --rotate; a code's without its quiet zone; "
             "default: the size it loads at, e.g. a code's ;module=).")] = None,
    rotate: Annotated[float, typer.Option(help="Rotation, degrees CCW about +z.")] = 0.0,
    mode: Annotated[str, typer.Option(help="; ".join(f"{k}: {m.description}" for k, m in
                                                     PROJECTIONS.items()) + ".")] = "planar",
    hatch: Annotated[float | None, typer.Option(help="Fill filled regions with hatch lines this "
                                                     "far apart, mm (default: outlines "
                                                     "only).")] = None,
    hatch_angle: Annotated[float, typer.Option(help="Hatch direction, degrees from +x.")] = 0.0,
    cross: Annotated[bool, typer.Option(help="Cross-hatch (a second hatch at +90°).")] = False,
    fill: Annotated[str, typer.Option(help="A DXF's closed outlines: auto (fills where the "
                                           "file has hatches, solids, wide polylines, text; "
                                           "other outlines as lines), all (fill every closed "
                                           "outline), none (outlines only).")] = "auto",
    beam: Annotated[float, typer.Option(help="Beam width, mm: strokes at least this wide are "
                                             "marked as their area, thinner ones as lines; a "
                                             "code's default hatch is no coarser.")] = BEAM_MM,
    force: Annotated[bool, typer.Option(help="Write the job even when a code would not decode "
                                             "from the planned marks.")] = False,
    power: Annotated[float, typer.Option(help="Laser power, % of full.")] = 30.0,
    frequency: Annotated[float, typer.Option(help="Pulse frequency, kHz.")] = 20.0,
    speed: Annotated[float, typer.Option(help="Mark speed, mm/s.")] = 500.0,
    jump_speed: Annotated[float, typer.Option(help="Jump speed, mm/s.")] = 3000.0,
    run: Annotated[bool, typer.Option(help="Also mark the job on the rig (with --preview, --restart, "
                                           "--resume, --cut-path, --inspect).")] = False,
    preview: Preview = False, resume: Resume = False, restart: Restart = False,
    cut_path: CutPath = None, inspect: Inspect = None, rig: Rig = None,
    field: Field = None, workpiece: Workpiece = "step-block", seed: Seed = 0,
) -> None:
    """Place a pattern with its centre at X Y, WIDTH mm wide, turned by --rotate; project it
    onto the measured surface (--mode) and write the mark job. The job is refused,
    and nothing is written, when any point lies outside the scan field or the focus range, over
    a hole in the cloud or over a steep wall. --run then marks it: the laser is on only while
    marking, off at once on any fault, and an interrupted job resumes with --resume."""
    from insitu.marking import LaserParams, Placement, read_job
    from insitu.services import mark as svc
    from insitu.services.station import connect

    check_output(out, ".json")
    projection_mode(mode)
    if inspect is not None:
        check_output(inspect, ".png")
    if (preview or resume or restart or cut_path or inspect is not None) and not run:
        fail("--preview, --resume, --restart, --cut-path and --inspect go with --run")
    check_run_options(resume, restart, cut_path)
    if not 0 <= power <= 100:
        fail(f"--power {power:g}: expected 0 … 100 %")
    for name, value in (("--frequency", frequency), ("--speed", speed),
                        ("--jump-speed", jump_speed)):
        if not value > 0:
            fail(f"{name} {value:g}: expected a positive number")
    if fill not in FILL_MODES:
        fail(f"--fill {fill!r}: expected one of {', '.join(FILL_MODES)}")
    if not beam > 0:
        fail(f"--beam {beam:g}: expected a positive number")
    placement = Placement(pattern, at, width, rotate, mode, hatch, hatch_angle, cross, fill,
                          beam)
    laser = LaserParams(power_pct=power, frequency_khz=frequency, mark_speed_mm_s=speed,
                        jump_speed_mm_s=jump_speed)
    with connect(rig, workpiece, seed, field=field) as station:
        with progress_bar("projecting") as progress:
            progress(0, 1)
            plan = svc.plan_mark(cloud, placement, station.driver, laser, force)
        if resume and (not out.exists() or read_job(out).digest() != plan.job.digest()):
            fail(f"--resume: {out} does not hold this job; run without --resume to start it")
        if not resume:
            svc.save_job(out, plan.job)
        _summary(out, placement, plan, station.field)
        if run:
            run_on_station(station, plan.job, out, resume, preview, inspect, restart, cut_path)


def _summary(out: Path, placement, plan, field: Path | None) -> None:
    pts = plan.projection.points
    (cx, cy), (w, h) = plan.pattern.centre, plan.pattern.size
    e = plan.estimate
    table = Table(title=f"mark job → {out}", show_header=False)
    table.add_row("pattern", f"{plan.pattern.name}: {w:.3f} × {h:.3f} mm, centre "
                             f"({cx:.3f}, {cy:.3f})")
    fill = (f"hatch {placement.hatch_mm:g} mm at {placement.hatch_angle_deg:g}°"
            + (" crossed" if placement.cross else "")) if placement.hatch_mm else "outlines"
    if placement.hatch_mm is None and plan.pattern.code is not None:
        fill = "hatch {:.4g} mm at {:g}° along the modules".format(
            *placement.code_hatch(plan.pattern))
    for note in plan.pattern.notes:
        table.add_row("loaded", note)
    table.add_row("marks", f"{len(plan.job.paths):,} paths, {len(pts):,} points ({fill})")
    mode = placement.mode + (f", worst stretch {plan.projection.max_stretch:.2%}"
                             if PROJECTIONS[placement.mode].stretches else "")
    table.add_row("projection", mode)
    for c in plan.codes:
        table.add_row("decodes", f"{'yes' if c.ok else 'NO'}: {c.name} (module "
                                 f"{c.module_mm:.3g} mm" + (f", read {c.decoded!r})" if not c.ok
                                                            else ")"))
    table.add_row("z on the surface, mm", f"{pts[:, 2].min():.3f} … {pts[:, 2].max():.3f}")
    table.add_row("field correction", str(field) if field else "none")
    table.add_row("estimated time", f"{e.total_s:.1f} s (mark {e.mark_mm:.0f} mm, jump "
                                    f"{e.jump_mm:.0f} mm)")
    console.print(table)
