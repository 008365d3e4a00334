"""``insitu inspect``: read a marked pattern back from a camera image, without marking — or
read and grade every code in a photograph that comes without a plan."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from insitu.cli.common import bounded, check_output, console, one_line_errors
from insitu.cli.job import print_read_back
from insitu.cli.options import Field, Mode, Rig, Seed, Workpiece
from insitu.errors import ConfigError
from insitu.marking.modes import projection_mode
from insitu.patterns.load import sources_help
from insitu.patterns.vector import BEAM_MM

Image = Annotated[Path, typer.Argument(
    metavar="IMAGE.png", help="The side camera's frame of the marked part (the laser off), or "
    "without --cloud, --pattern and --at any photograph (PNG, JPEG, WebP, …).")]
Cloud = Annotated[Path | None, typer.Option(help="Measured point cloud (.ply) the pattern "
                                                 "was placed on.")]
AsMarked = Annotated[str | None, typer.Option(
    "--pattern", help=f"As marked: a file or spec: {sources_help()}.")]
AtAsMarked = Annotated[tuple[float, float] | None, typer.Option(
    "--at", metavar="X Y", callback=bounded("position_mm"),
    help="Centre of the pattern X Y, mm, world frame, as marked.")]
Out = Annotated[Path | None, typer.Option("-o", "--output", help="Read-back picture to write "
                                                                 "(.png; needed with a plan).")]
WidthAsMarked = Annotated[float | None, typer.Option(
    "--width", callback=bounded("length_mm"), help="Width as marked, mm (insitu mark --width).")]
RotateAsMarked = Annotated[float, typer.Option(
    "--rotate", callback=bounded("angle_deg"), help="Rotation as marked, degrees CCW about +z.")]
HatchAsMarked = Annotated[float | None, typer.Option(
    "--hatch", callback=bounded("length_mm"), help="Hatch spacing as marked, mm.")]
BeamWidth = Annotated[float, typer.Option("--beam", callback=bounded("length_mm"),
                                          help="Beam width, mm.")]
JobAsMarked = Annotated[Path | None, typer.Option(
    "--job", metavar="JOB.json", help="The job as marked: a pattern with fields ({serial}, "
    "{date}, --var …) is read back as that job rendered it (its variable_data).")]


@one_line_errors
def inspect(image: Image, cloud: Cloud = None, pattern: AsMarked = None, at: AtAsMarked = None,
            out: Out = None, width: WidthAsMarked = None, rotate: RotateAsMarked = 0.0,
            mode: Mode = "planar", hatch: HatchAsMarked = None, beam: BeamWidth = BEAM_MM,
            job: JobAsMarked = None, rig: Rig = None, field: Field = None,
            workpiece: Workpiece = "step-block", seed: Seed = 0) -> None:
    """Read a mark back from IMAGE (the station's camera, as calibrated): the pattern is
    planned again as `insitu mark` placed it (same options), the image rectified onto the
    cloud's surface around it, a code decoded and graded. Writes the picture of the mark with
    the plan over it and prints what was decoded, the offset from the plan and the grade;
    exit 1 when a code does not read as planned.

    Without --cloud, --pattern and --at, IMAGE is any photograph of marked codes: every QR,
    Micro QR and Data Matrix code in it is decoded and graded (rectified by its corners; -o
    writes the rectified codes); exit 1 when none reads."""
    from insitu.formats.images import read_image
    from insitu.formats.pointcloud import read_ply
    from insitu.marking import Placement
    from insitu.services.inspect import as_marked, read_back
    from insitu.services.mark import save_image
    from insitu.services.plan import plan_mark
    from insitu.services.station import connect

    plan_options = {"--cloud": cloud, "--pattern": pattern, "--at": at}
    if all(v is None for v in plan_options.values()):
        _inspect_photo(image, out)
        return
    missing = [k for k, v in {**plan_options, "-o": out}.items() if v is None]
    if missing:
        raise ConfigError(f"inspect with a plan needs {', '.join(missing)} too (or none of "
                         "--cloud, --pattern, --at to read IMAGE as a photograph)")
    check_output(out, ".png")
    projection_mode(mode)
    placement = as_marked(Placement(pattern, at, width, rotate, mode, hatch, beam_mm=beam), job)
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


def _inspect_photo(image: Path, out: Path | None) -> None:
    """Decode and grade every 2-D code in the photograph ``image``; print one row each."""
    from rich.table import Table
    from rich.text import Text

    from insitu.formats.images import read_image
    from insitu.services.mark import save_image
    from insitu.vision.code_photo import photo_picture, read_photo
    from insitu.vision.dpm_grade import letter

    if out is not None:
        check_output(out, ".png")
    codes = read_photo(read_image(image))
    if not codes:
        console.print(f"{image}: no QR, Micro QR or Data Matrix code read", highlight=False)
        raise typer.Exit(1)
    table = Table(title=f"codes in {image}")
    for head in ("code", "decoded", "module px", "UEC", "grade", "parameters"):
        table.add_column(head)
    for c in codes:
        uec = "-" if c.uec is None else f"{c.uec:.2f} {letter(c.uec_grade)}"
        table.add_row(Text(c.symbology), Text(c.text), f"{c.module_px:.1f}", uec,
                      letter(c.overall), Text(c.grades.summary()))
    console.print(table)
    if out is not None:
        save_image(out, photo_picture(codes))
        console.print(f"wrote {out}", highlight=False)
