"""``insitu inspect``: read a marked pattern back from a camera image, without marking."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from insitu.cli.common import bounded, check_output, console, one_line_errors
from insitu.cli.job import Field, Rig, Seed, Workpiece, print_read_back
from insitu.marking.modes import PROJECTIONS, projection_mode
from insitu.patterns.load import sources_help
from insitu.patterns.vector import BEAM_MM


@one_line_errors
def inspect(
    image: Annotated[Path, typer.Argument(metavar="IMAGE.png", help="The side camera's frame "
                                          "of the marked part (the laser off).")],
    cloud: Annotated[Path, typer.Option(help="Measured point cloud (.ply) the pattern was "
                                             "placed on.")],
    pattern: Annotated[str, typer.Option(help=f"As marked: a file or spec: {sources_help()}.")],
    at: Annotated[tuple[float, float], typer.Option(metavar="X Y",
        callback=bounded("position_mm"), help="Centre of the pattern X Y, mm, world frame, "
                                              "as marked.")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Read-back picture to write "
                                                             "(.png).")],
    width: Annotated[float | None, typer.Option(
        callback=bounded("length_mm"), help="Width as marked, mm (insitu mark --width).")] = None,
    rotate: Annotated[float, typer.Option(
        callback=bounded("angle_deg"), help="Rotation as marked, degrees CCW about +z.")] = 0.0,
    mode: Annotated[str, typer.Option(help="; ".join(f"{k}: {m.description}" for k, m in
                                                     PROJECTIONS.items()) + ".")] = "planar",
    hatch: Annotated[float | None, typer.Option(
        callback=bounded("length_mm"), help="Hatch spacing as marked, mm.")] = None,
    beam: Annotated[float, typer.Option(
        callback=bounded("length_mm"), help="Beam width, mm.")] = BEAM_MM,
    job: Annotated[Path | None, typer.Option(
        metavar="JOB.json", help="The job as marked: a pattern with fields ({serial}, {date}, "
        "--var …) is read back as that job rendered it (its variable_data).")] = None,
    rig: Rig = None, field: Field = None, workpiece: Workpiece = "step-block", seed: Seed = 0,
) -> None:
    """Read a mark back from IMAGE (the station's camera, as calibrated): the pattern is
    planned again as `insitu mark` placed it (same options), the image rectified onto the
    cloud's surface around it, a code decoded and graded. Writes the picture of the mark with
    the plan over it and prints what was decoded, the offset from the plan and the grade;
    exit 1 when a code does not read as planned."""
    from insitu.errors import FormatError
    from insitu.formats.images import read_image
    from insitu.formats.pointcloud import read_ply
    from insitu.marking import Placement, read_job
    from insitu.patterns.fields import is_template
    from insitu.services.inspect import read_back
    from insitu.services.mark import plan_mark, save_image
    from insitu.services.serials import job_variables, render_placement
    from insitu.services.station import connect

    check_output(out, ".png")
    projection_mode(mode)
    placement = Placement(pattern, at, width, rotate, mode, hatch, beam_mm=beam)
    if is_template(pattern):
        if job is None:
            raise FormatError(f"--pattern {pattern!r} has fields: name the job it was marked "
                              "with (--job JOB.json), whose texts say what was marked")
        values = job_variables(read_job(job), job)
        if values is None:
            raise FormatError(f"{job}: no variable_data: not the job of a pattern with fields")
        placement = render_placement(placement, values.variables())
    measured = read_ply(cloud)
    with connect(rig, workpiece, seed, field=field) as station:
        cam = station.rig.camera
        frame = read_image(image, expect=(cam.width, cam.height), expected="the camera is")
        plan = plan_mark(measured, placement, station.driver, force=True)
        result = read_back(station, [plan], measured, image=frame, beam_mm=beam)
    save_image(out, result.picture)
    print_read_back(result)
    console.print(f"wrote {out}", highlight=False)
    if not result.ok:
        raise typer.Exit(1)
