"""``insitu mark``: place a pattern on a measured cloud, write the mark job, optionally mark it."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table
from rich.text import Text

from insitu.cli.common import (
    check_output,
    console,
    fail,
    missing,
    one_line_errors,
    progress_bar,
    warn,
)
from insitu.cli.job import check_run_options, pen_text, run_on_station
from insitu.cli.options import (
    At,
    Beam,
    CounterPath,
    Cross,
    CutPath,
    Field,
    Fill,
    Force,
    Frequency,
    Hatch,
    HatchAngle,
    JumpSpeed,
    Mode,
    Paint,
    PartPose,
    PatternSpec,
    PenName,
    PensFile,
    PosePath,
    Power,
    Preview,
    Restart,
    Resume,
    Rig,
    Rotate,
    Seed,
    SerialStart,
    Speed,
    Vars,
    Width,
    Workpiece,
)
from insitu.patterns.vector import BEAM_MM

Recipe = Annotated[Path | None, typer.Option(
    help="A production recipe (insitu recipe new): locate its part in the cloud and plan all "
         "its placements, moved where the part lies, as one job (with --run, --rig, --field, "
         "--workpiece, --seed; its serial from the recipe's counter).")]
Run = Annotated[bool, typer.Option(help="Also mark the job on the rig (with --preview, "
                                        "--restart, --resume, --cut-path, --inspect).")]
ReadBack = Annotated[Path | None, typer.Option(
    help="Read the marks back with the camera: write the picture of each mark rectified onto "
         "the surface with the plan over it (.png; the raw frame beside it as NAME.raw.png) "
         "and print what was decoded, the offset and the grade.")]
LABELS = {"pattern": "loaded"}       # a finding's row name where it is not its check's

ProjectOut = Annotated[Path | None, typer.Option(
    metavar="P.insitu.json", help="Also write a project naming the cloud, this placement, the "
    "rig and the job, to go on with it in insitu gui.")]


@one_line_errors
def mark(
    cloud: Annotated[Path, typer.Option(help="Measured point cloud (.ply) of the part.")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Mark job to write (.json).")],
    pattern: PatternSpec = None, at: At = None, recipe: Recipe = None, width: Width = None,
    rotate: Rotate = 0.0, part_pose: PosePath = None, mode: Mode = "planar",
    hatch: Hatch = None, hatch_angle: HatchAngle = 0.0, cross: Cross = False,
    fill: Fill = "auto", beam: Beam = BEAM_MM, paint: Paint = "threshold",
    force: Force = False, pen: PenName = None,
    pens: PensFile = None, power: Power = None, frequency: Frequency = None,
    speed: Speed = None, jump_speed: JumpSpeed = None, run: Run = False,
    preview: Preview = False, resume: Resume = False, restart: Restart = False,
    cut_path: CutPath = None, inspect: ReadBack = None, rig: Rig = None, field: Field = None,
    workpiece: Workpiece = "step-block", seed: Seed = 0, pose: PartPose = (0.0, 0.0, 0.0),
    fields: Vars = None, counter: CounterPath = None, serial_start: SerialStart = None,
    project: ProjectOut = None,
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
    from insitu.formats.pointcloud import read_ply
    from insitu.patterns.fields import parse_fields
    from insitu.services.mark_job import JobRequest, laser_of, write_mark_job
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
    _check_options(pattern, at, project, inspect, run, preview, resume, restart, cut_path)
    placement, located = _placement(pattern, at, width, rotate, mode, hatch, hatch_angle, cross,
                                    fill, beam, paint, part_pose, cloud)
    laser, table = laser_of(pen, pens, power_pct=power, frequency_khz=frequency,
                            mark_speed_mm_s=speed, jump_speed_mm_s=jump_speed)
    measured = read_ply(cloud)
    with connect(rig, workpiece, seed, field=field, pose=pose) as station:
        with progress_bar("projecting") as progress:
            progress(0, 1)
            written = write_mark_job(station, JobRequest(
                out, (placement,), measured, cloud, laser, table, force,
                parse_fields(fields or []), counter, serial_start, resume, marking=run))
        _summary(out, placement, written, station.field, part_pose, located)
        if project is not None:
            write_mark_project(project, cloud, measured.rig, placement, out, rig, field,
                               workpiece, seed)
            console.print(f"wrote {project} (insitu gui {project})", highlight=False)
        if run:
            run_on_station(station, written.job, out, resume, preview, inspect, restart,
                           cut_path, read=([o.plan for o in written.outcomes], measured))


def _check_options(pattern, at, project, inspect, run, preview, resume, restart, cut_path):
    """One line for a missing option or options that do not go together."""
    if pattern is None or at is None:
        missing("--pattern: missing; expected a word" if pattern is None
                else "--at: missing; expected 2 numbers X Y")
    if project is not None:
        check_project_output(project)
    if inspect is not None:
        check_output(inspect, ".png")
    if (preview or resume or restart or cut_path or inspect is not None) and not run:
        fail("--preview, --resume, --restart, --cut-path and --inspect go with --run")
    check_run_options(resume, restart, cut_path)


def _placement(pattern, at, width, rotate, mode, hatch, hatch_angle, cross, fill, beam, paint,
               part_pose, cloud):
    """(the placement in the world, the part's pose file or None): with --part-pose the
    placement is given in the part's frame and moved where the part lies."""
    from insitu.cli.common import warn
    from insitu.formats.pose import load_pose
    from insitu.marking import Placement
    from insitu.marking.modes import projection_mode
    from insitu.patterns.dxf import FILL_MODES
    from insitu.patterns.vector import PAINT_MODES

    projection_mode(mode)
    if fill not in FILL_MODES:
        fail(f"--fill {fill!r}: expected one of {', '.join(FILL_MODES)}")
    if paint not in PAINT_MODES:
        fail(f"--paint {paint!r}: expected one of {', '.join(PAINT_MODES)}")
    placement = Placement(pattern, at, width, rotate, mode, hatch, hatch_angle, cross, fill,
                          beam, paint=paint)
    if part_pose is None:
        return placement, None
    located = load_pose(part_pose)
    if len(located.inputs) > 1 and Path(located.inputs[1]).name != cloud.name:
        warn(f"{part_pose} was located on {located.inputs[1]}, not on {cloud}")
    return placement.in_world(located.matrix), located


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


def record_rows(table: Table, rec) -> None:
    """The rows of a job's variable data (``rec``: its record, None: none): the texts
    rendered and the serial issued."""
    if rec is not None:
        for t in rec.texts:
            table.add_row("renders", t.text)
        if rec.serial is not None:
            table.add_row("serial", f"{rec.serial} (issued from {rec.counter})")


def _summary(out: Path, placement, written, field: Path | None,
             part_pose: Path | None = None, located=None) -> None:
    """The job's table: where it was placed, every finding of its verdict (the lines the
    application's Place dock shows), the marks, the laser and the time."""
    outcome = written.outcomes[0]
    plan = outcome.plan
    pts, e = plan.projection.points, plan.estimate
    (cx, cy), (w, h) = plan.pattern.centre, plan.pattern.size
    table = Table(title=f"mark job → {out}", show_header=False)
    if located is not None:
        table.add_row("part pose", f"{part_pose}: x {located.x_mm:.3f}, y {located.y_mm:.3f} "
                                   f"mm, turned {located.angle_deg:.3f}°; placed at world "
                                   f"({placement.at_mm[0]:.3f}, {placement.at_mm[1]:.3f}), "
                                   f"{placement.rotate_deg:.3f}°")
    table.add_row("pattern", f"{plan.pattern.name}: {w:.3f} × {h:.3f} mm, centre "
                             f"({cx:.3f}, {cy:.3f})")
    for f in outcome.findings:
        if f.check == "rig":            # the station's word on the cloud, before the job's
            warn(f.text)
            continue
        table.add_row(Text("warning", "yellow") if f.level == "warning" else
                      LABELS.get(f.check, f.check), f.text)
    record_rows(table, written.record)
    table.add_row("marks", f"{len(plan.job.paths):,} paths, {len(pts):,} points "
                           f"({_fill(placement, plan.pattern)})")
    over = plan.job.paths[0].laser
    if over is not None and over.pen:
        table.add_row("pen", f"{over.pen}: {pen_text(plan.job, 0)}")
    table.add_row("z on the surface, mm", f"{pts[:, 2].min():.3f} … {pts[:, 2].max():.3f}")
    table.add_row("field correction", str(field) if field else "none")
    table.add_row("estimated time", f"{e.total_s:.1f} s (mark {e.mark_mm:.0f} mm, jump "
                                    f"{e.jump_mm:.0f} mm)")
    console.print(table)


def _fill(placement, pattern) -> str:
    """How the placement is filled: its hatch, a code's along its modules, or outlines."""
    if placement.hatch_mm:
        return (f"hatch {placement.hatch_mm:g} mm at {placement.hatch_angle_deg:g}°"
                + (" crossed" if placement.cross else ""))
    if pattern.code is not None:
        return "hatch {:.4g} mm at {:g}° along the modules".format(*placement.code_hatch(pattern))
    return "outlines"
