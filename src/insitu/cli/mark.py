"""``insitu mark``: place a pattern on a measured cloud, write the mark job, optionally mark it."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table
from rich.text import Text

from insitu.cli.common import (bounded, check_output, console, fail, missing,
                               one_line_errors, progress_bar, warn)
from insitu.cli.job import (CutPath, Field, PartPose, Preview, Restart, Resume, Rig, Seed,
                            Workpiece, check_run_options, pen_text, run_on_station)
from insitu.marking.modes import PROJECTIONS, projection_mode
from insitu.patterns.dxf import FILL_MODES
from insitu.patterns.load import sources_help
from insitu.patterns.vector import BEAM_MM, PAINT_MODES


@one_line_errors
def mark(
    cloud: Annotated[Path, typer.Option(help="Measured point cloud (.ply) of the part.")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Mark job to write (.json).")],
    pattern: Annotated[str | None, typer.Option(
        help=f"A file or spec: {sources_help()}. Required without --recipe.")] = None,
    at: Annotated[tuple[float, float] | None, typer.Option(metavar="X Y",
        callback=bounded("position_mm"), help="Centre of the pattern X Y, mm, "
                                              "world frame (the part's with --part-pose). "
                                              "Required without --recipe.")] = None,
    recipe: Annotated[Path | None, typer.Option(
        help="A production recipe (insitu recipe new): locate its part in the cloud and "
             "plan all its placements, moved where the part lies, as one job (with --run, "
             "--rig, --field, --workpiece, --seed; its serial from the recipe's "
             "counter).")] = None,
    width: Annotated[float | None, typer.Option(
        callback=bounded("length_mm"),
        help="Width of the pattern, mm (before --rotate; a code's without its quiet zone; "
             "default: the size it loads at, e.g. a code's ;module=).")] = None,
    rotate: Annotated[float, typer.Option(
        callback=bounded("angle_deg"), help="Rotation, degrees CCW about +z (from the "
                                            "part's x axis with --part-pose).")] = 0.0,
    part_pose: Annotated[Path | None, typer.Option(
        help="POSE.json of `insitu locate`: --at, --rotate and --hatch-angle are then in the "
             "part's own frame, moved to where the part lies.")] = None,
    mode: Annotated[str, typer.Option(help="; ".join(f"{k}: {m.description}" for k, m in
                                                     PROJECTIONS.items()) + ".")] = "planar",
    hatch: Annotated[float | None, typer.Option(
        callback=bounded("length_mm"), help="Fill filled regions with hatch lines this "
                                            "far apart, mm (default: outlines "
                                            "only).")] = None,
    hatch_angle: Annotated[float, typer.Option(
        callback=bounded("angle_deg"), help="Hatch direction, degrees from +x.")] = 0.0,
    cross: Annotated[bool, typer.Option(help="Cross-hatch (a second hatch at +90°).")] = False,
    fill: Annotated[str, typer.Option(help="A DXF's closed outlines: auto (fills where the "
                                           "file has hatches, solids, wide polylines, text; "
                                           "other outlines as lines), all (fill every closed "
                                           "outline), none (outlines only).")] = "auto",
    beam: Annotated[float, typer.Option(
        callback=bounded("length_mm"), help="Beam width, mm: strokes at least this wide are "
                                            "marked as their area, thinner ones as lines; a "
                                            "code's default hatch is no coarser.")] = BEAM_MM,
    paint: Annotated[str, typer.Option(help="An SVG's shaded paints (gradients, patterns, "
                                            "opacity, masks): threshold (marked where darker "
                                            "than 50 %) or dither (dots).")] = "threshold",
    force: Annotated[bool, typer.Option(help="Write the job even when a code would not decode "
                                             "from the planned marks.")] = False,
    pen: Annotated[str | None, typer.Option(
        help="The pen (named laser set: power, frequency, speeds, passes, delays, wobble) of "
             "--pens to mark with (default: its default pen).")] = None,
    pens: Annotated[Path | None, typer.Option(
        metavar="PENS.json", help="Pens file (insitu-pens/1) or a project (.insitu.json) "
                                  "whose pens --pen picks from (default: the built-in mark, "
                                  "fine, deep, bold).")] = None,
    power: Annotated[float | None, typer.Option(
        callback=bounded("power_pct"), help="Laser power, % of full (default: the pen's, "
                                            "else 30).")] = None,
    frequency: Annotated[float | None, typer.Option(
        callback=bounded("frequency_khz"), help="Pulse frequency, kHz (default: the pen's, "
                                                "else 20).")] = None,
    speed: Annotated[float | None, typer.Option(
        callback=bounded("mark_speed_mm_s"), help="Mark speed, mm/s (default: the pen's, "
                                                  "else 500).")] = None,
    jump_speed: Annotated[float | None, typer.Option(
        callback=bounded("jump_speed_mm_s"), help="Jump speed, mm/s (default: the pen's, "
                                                  "else 3000).")] = None,
    run: Annotated[bool, typer.Option(help="Also mark the job on the rig (with --preview, --restart, "
                                           "--resume, --cut-path, --inspect).")] = False,
    preview: Preview = False, resume: Resume = False, restart: Restart = False,
    cut_path: CutPath = None,
    inspect: Annotated[Path | None, typer.Option(
        help="Read the marks back with the camera: write the picture of each mark rectified "
             "onto the surface with the plan over it (.png; the raw frame beside it as "
             "NAME.raw.png) and print what was decoded, the offset and the grade.")] = None,
    rig: Rig = None,
    field: Field = None, workpiece: Workpiece = "step-block", seed: Seed = 0,
    pose: PartPose = (0.0, 0.0, 0.0),
    fields: Annotated[list[str] | None, typer.Option(
        "--var", metavar="NAME=VALUE", help="A value for {NAME} in the pattern's text "
        "(again for more fields); {serial}, {date}, {time} are built in.")] = None,
    counter: Annotated[Path | None, typer.Option(
        help="Serial counter for {serial} (default: serial.counter.json beside the job).")] = None,
    serial_start: Annotated[int | None, typer.Option(
        help="Create the serial counter, its first serial this.")] = None,
    project: Annotated[Path | None, typer.Option(
        metavar="P.insitu.json", help="Also write a project naming the cloud, this placement, "
        "the rig and the job, to go on with it in insitu gui.")] = None,
) -> None:
    """Place a pattern with its centre at X Y, WIDTH mm wide, turned by --rotate; project it
    onto the measured surface (--mode) and write the mark job. The job is refused,
    and nothing is written, when any point lies outside the scan field or the focus range, over
    a hole in the cloud or over a steep wall. --run then marks it: the laser is on only while
    marking, off at once on any fault, and an interrupted job resumes with --resume.
    Variable data: a text with {serial:05d}, {date:%Y-%m-%d}, {time:%H%M} or {NAME}
    (--var NAME=VALUE) is rendered when the job is planned; {serial} takes the counter's next
    serial, issued once the job passed its checks, never handed out again (a resume marks the
    job's own)."""
    from insitu.formats.pens import DEFAULT_PENS, PenTable
    from insitu.formats.pointcloud import read_ply
    from insitu.formats.project import load_pens
    from insitu.marking import LaserParams, Placement, read_job
    from insitu.services import mark as svc
    from insitu.services.station import connect

    check_output(out, ".json")
    if recipe is not None:
        from insitu.cli.recipe import check_recipe_options, mark_recipe

        check_recipe_options(**{"--pattern": pattern, "--at": at, "--width": width,
                                "--hatch": hatch, "--var": fields, "--counter": counter,
                                "--serial-start": serial_start is not None, "--resume": resume,
                                "--restart": restart, "--cut-path": cut_path})
        return mark_recipe(recipe, cloud, out, run, preview, inspect, rig, field, workpiece,
                           seed)
    if pattern is None or at is None:
        missing("--pattern: missing; expected a word" if pattern is None
                else "--at: missing; expected 2 numbers X Y")
    if project is not None:
        check_project_output(project)
    projection_mode(mode)
    if inspect is not None:
        check_output(inspect, ".png")
    if (preview or resume or restart or cut_path or inspect is not None) and not run:
        fail("--preview, --resume, --restart, --cut-path and --inspect go with --run")
    check_run_options(resume, restart, cut_path)
    if fill not in FILL_MODES:
        fail(f"--fill {fill!r}: expected one of {', '.join(FILL_MODES)}")
    if paint not in PAINT_MODES:
        fail(f"--paint {paint!r}: expected one of {', '.join(PAINT_MODES)}")
    placement = Placement(pattern, at, width, rotate, mode, hatch, hatch_angle, cross, fill,
                          beam, paint=paint)
    located = None
    if part_pose is not None:
        from insitu.formats.pose import load_pose

        located = load_pose(part_pose)
        if len(located.inputs) > 1 and Path(located.inputs[1]).name != cloud.name:
            warn(f"{part_pose} was located on {located.inputs[1]}, not on {cloud}")
        placement = placement.in_world(located.matrix)
    given = {k: v for k, v in (("power_pct", power), ("frequency_khz", frequency),
                               ("mark_speed_mm_s", speed), ("jump_speed_mm_s", jump_speed))
             if v is not None}
    table = None
    if pen is not None or pens is not None:     # the pen, its fields the options give replaced
        base = (load_pens(pens) if pens is not None else DEFAULT_PENS).pen(
            pen, "--pen" if pens is None else str(pens))
        chosen = base.model_copy(update=given)
        table = PenTable(default=chosen.name, pens=(chosen,))
        given = {k: getattr(chosen, k) for k in LaserParams.model_fields}
    laser = LaserParams(**given)
    measured = read_ply(cloud)
    with connect(rig, workpiece, seed, field=field, pose=pose) as station:
        if run and (warning := station.check_source(cloud, measured.rig, "cloud")):
            warn(warning)
        with progress_bar("projecting") as progress:
            progress(0, 1)
            plan, rec = _plan(out, placement, lambda p: svc.plan_mark(
                measured, p, station.driver, laser, force, table), resume, fields, counter,
                serial_start)
        if resume and (not out.exists() or read_job(out).digest() != plan.job.digest()):
            fail(f"--resume: {out} does not hold this job; run without --resume to start it")
        _summary(out, placement, plan, station.field, rec, part_pose, located)
        if project is not None:
            write_mark_project(project, cloud, measured.rig, placement, out, rig, field,
                               workpiece, seed)
            console.print(f"wrote {project} (insitu gui {project})", highlight=False)
        if run:
            run_on_station(station, plan.job, out, resume, preview, inspect, restart, cut_path,
                           read=([plan], measured))


def check_project_output(path: Path) -> None:
    """A project's name ends in .insitu.json, in a folder that exists."""
    from insitu.formats.project import SUFFIX

    check_output(path)
    if not path.name.endswith(SUFFIX):
        fail(f"--project {path}: expected a *{SUFFIX} file name")


def write_mark_project(path: Path, cloud: Path, record, placement, job: Path, rig, field,
                       workpiece: str, seed: int) -> None:
    """The project of ``insitu gui`` holding what ``insitu mark`` planned: the cloud, the
    placement, the rig (the cloud's binning), the field correction and the job."""
    from insitu.formats.project import SIM_BINNING, Project, RigChoice, write_project

    binning = int((record or {}).get("binning", SIM_BINNING))
    write_project(path, Project(rig=RigChoice(workpiece, seed, binning, rig),
                                field_correction=field, cloud=cloud, placements=(placement,),
                                selected=0, job=job))


def _plan(out: Path, placement, plan_mark, resume: bool, fields, counter, start):
    """(plan, variable-data record or None): planned and written with the serial taken from
    the counter, or, with ``resume``, planned again as the job at ``out`` was (nothing
    written, no serial taken)."""
    from insitu.marking import read_job
    from insitu.patterns.fields import parse_fields
    from insitu.services import serials

    values = parse_fields(fields or [])
    if resume:
        if counter is not None or start is not None:
            fail("--resume marks the job's own serial: drop --counter and --serial-start")
        plan = serials.replan(out, [placement], lambda ps: plan_mark(ps[0]), values)
        return plan, serials.job_variables(read_job(out), out) if out.exists() else None
    done = serials.plan_and_save(out, [placement], lambda ps: plan_mark(ps[0]),
                                 lambda plan: plan.job, counter=counter, fields=values,
                                 start=start)
    return done.result, done.record


def record_rows(table: Table, rec) -> None:
    """The rows of a job's variable data (``rec``: its record, None: none): the texts
    rendered and the serial issued."""
    if rec is not None:
        for t in rec.texts:
            table.add_row("renders", t.text)
        if rec.serial is not None:
            table.add_row("serial", f"{rec.serial} (issued from {rec.counter})")


def _summary(out: Path, placement, plan, field: Path | None, rec=None,
             part_pose: Path | None = None, located=None) -> None:
    pts = plan.projection.points
    (cx, cy), (w, h) = plan.pattern.centre, plan.pattern.size
    e = plan.estimate
    table = Table(title=f"mark job → {out}", show_header=False)
    if located is not None:
        table.add_row("part pose", f"{part_pose}: x {located.x_mm:.3f}, y {located.y_mm:.3f} "
                                   f"mm, turned {located.angle_deg:.3f}°; placed at world "
                                   f"({placement.at_mm[0]:.3f}, {placement.at_mm[1]:.3f}), "
                                   f"{placement.rotate_deg:.3f}°")
    table.add_row("pattern", f"{plan.pattern.name}: {w:.3f} × {h:.3f} mm, centre "
                             f"({cx:.3f}, {cy:.3f})")
    fill = (f"hatch {placement.hatch_mm:g} mm at {placement.hatch_angle_deg:g}°"
            + (" crossed" if placement.cross else "")) if placement.hatch_mm else "outlines"
    if placement.hatch_mm is None and plan.pattern.code is not None:
        fill = "hatch {:.4g} mm at {:g}° along the modules".format(
            *placement.code_hatch(plan.pattern))
    for note in plan.pattern.notes:
        table.add_row(Text("warning", "yellow") if note.startswith("warning:") else "loaded",
                      note.removeprefix("warning: "))
    record_rows(table, rec)
    table.add_row("marks", f"{len(plan.job.paths):,} paths, {len(pts):,} points ({fill})")
    over = plan.job.paths[0].laser
    if over is not None and over.pen:
        table.add_row("pen", f"{over.pen}: {pen_text(plan.job, 0)}")
    mode = placement.mode + (f", worst stretch {plan.projection.max_stretch:.2%}"
                             if PROJECTIONS[placement.mode].stretches else "")
    table.add_row("projection", mode)
    proj = plan.projection
    if proj.unmarked_mm > 0:
        table.add_row("unmarked at walls", f"{proj.unmarked_mm:.2f} mm of {proj.path_mm:.0f} mm "
                      f"of path ({proj.unmarked_fraction:.1%}): across a wall and where the "
                      "cloud does not show where it is")
    for c in plan.codes:
        table.add_row("decodes", f"{'yes' if c.ok else 'NO'}: {c.name} (module "
                                 f"{c.module_mm:.3g} mm" + (f", read {c.decoded!r})" if not c.ok
                                                            else ")"))
    table.add_row("z on the surface, mm", f"{pts[:, 2].min():.3f} … {pts[:, 2].max():.3f}")
    table.add_row("field correction", str(field) if field else "none")
    table.add_row("estimated time", f"{e.total_s:.1f} s (mark {e.mark_mm:.0f} mm, jump "
                                    f"{e.jump_mm:.0f} mm)")
    console.print(table)
