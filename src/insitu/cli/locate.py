"""``insitu locate REFERENCE CLOUD -o POSE.json``: where the part lies in a scan."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import cv2
import typer
from rich.table import Table

from insitu.cli.common import (
    bounded,
    bounded_each,
    check_output,
    console,
    one_line_errors,
    progress_bar,
)
from insitu.errors import ConfigError
from insitu.formats.images import read_image
from insitu.locate.part import LocateSettings

_D = LocateSettings()


Reference = Annotated[Path, typer.Argument(
    metavar="REFERENCE", help="The part: a mesh (STL, OBJ, PLY with faces) in its own frame, "
                              "mm, or a first scan's cloud (.ply).")]
Cloud = Annotated[Path, typer.Argument(metavar="CLOUD.ply", help="The scan to find it in.")]
Output = Annotated[Path, typer.Option("-o", "--output", help="POSE.json to write.")]
PreferAngle = Annotated[tuple[float, float] | None, typer.Option(
    metavar="LO HI", callback=bounded_each("angle_deg", "angle_deg"),
    help="A symmetric part: of poses that fit equally well, take the one turned within "
         "LO … HI degrees (e.g. -60 60 when parts are loaded roughly square).")]
MinFitness = Annotated[float, typer.Option(
    callback=bounded("fraction"), help="Share of the scan's points above the table the part "
                                       "must explain.")]
MinCoverage = Annotated[float, typer.Option(
    callback=bounded("fraction"), help="Share of the part's top the scan must measure.")]
MaxRmse = Annotated[float, typer.Option(callback=bounded("residual_mm"),
                                        help="Largest RMSE of the fit, mm.")]
TableZ = Annotated[float | None, typer.Option(
    callback=bounded("position_mm"), help="Height of the table, mm (default: found in the "
                                          "scan).")]
HeightCal = Annotated[Path | None, typer.Option(
    "--height-cal", help="The height calibration CLOUD was scanned with: its camera tells how "
                         "each scan line ends in the image, for a more precise turn "
                         "(default: unknown).")]
RoomLight = Annotated[Path | None, typer.Option(
    "--room-light", metavar="FRAME.png",
    help="A frame of that camera under the room light, laser off, the part as scanned (needs "
         "--height-cal): x, y and the turn then come from the top's edges seen whole in it, "
         "where they agree with the scan's.")]
ReferenceRoomLight = Annotated[Path | None, typer.Option(
    "--reference-room-light", metavar="FRAME.png",
    help="A scan REFERENCE's own room-light frame (insitu scan --room-light when it was "
         "scanned; needs --height-cal): its outline is fitted there (lines, circles), for the "
         "part's edges to be matched to.")]
Tolerance = Annotated[float, typer.Option(
    metavar="MM", callback=bounded("tolerance_mm"),
    help="The marking tolerance at the part's rim, mm: the pose is given only when 2σ of it "
         "there lies within (else refused, saying what would pin it down).")]
TurnBound = Annotated[float, typer.Option(
    "--turn-bound", metavar="DEG", callback=bounded("turn_bound_deg"),
    help="And only when 3σ of its turn lies within this, degrees (a small part's turn matters "
         "little at its rim, but is never far off).")]
TurnTolerance = Annotated[float | None, typer.Option(
    "--turn-tolerance", metavar="DEG", callback=bounded("turn_bound_deg"),
    help="And only when 2σ of its turn lies within this, degrees (the marks' own angle "
         "tolerance). Default: none, the rim's tolerance and --turn-bound decide.")]


@one_line_errors
def locate(reference: Reference, cloud: Cloud, out: Output, prefer_angle: PreferAngle = None,
           min_fitness: MinFitness = _D.min_fitness, min_coverage: MinCoverage = _D.min_coverage,
           max_rmse: MaxRmse = _D.max_rmse_mm, table_z: TableZ = None,
           height_cal: HeightCal = None, room_light: RoomLight = None,
           reference_room_light: ReferenceRoomLight = None,
           tolerance: Tolerance = _D.tolerance_mm,
           turn_bound_deg: TurnBound = _D.turn_bound_deg,
           turn_tolerance: TurnTolerance = None) -> None:
    """Find the part of REFERENCE in CLOUD: the table taken away, a global registration
    (FPFH features + RANSAC, and a search over turns about z), point-to-plane ICP kept flat
    on the table, then x, y and the turn from the edges the scan lines cross (or, with
    --room-light, from the edges in that frame). Writes
    POSE.json (T_world_part maps the part's frame to the world). Refused, nothing written,
    when the part is not found, fits poorly, is only partly in the scan, when a symmetric
    part fits nearly equally well turned (say which with --prefer-angle), or when the edges
    do not pin the pose down to --tolerance (the refusal says what would)."""
    from insitu.services.common import camera_model
    from insitu.services.height import load_height_calibration
    from insitu.services.locate import locate as svc

    check_output(out, ".json")
    for option, given in (("--room-light", room_light),
                          ("--reference-room-light", reference_room_light)):
        if given is not None and height_cal is None:
            raise ConfigError(f"{option} needs --height-cal: the frame's edges are placed "
                              "through the camera the scan was measured with")
    camera = (camera_model(load_height_calibration(height_cal).camera)
              if height_cal is not None else None)
    frame = (None if room_light is None else
             read_image(room_light, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH,
                        expect=(camera.width, camera.height), expected="the camera's frame is"))
    settings = LocateSettings(min_fitness=min_fitness, min_coverage=min_coverage,
                              max_rmse_mm=max_rmse, table_z_mm=table_z,
                              tolerance_mm=tolerance, turn_bound_deg=turn_bound_deg,
                              turn_tolerance_deg=turn_tolerance)
    with progress_bar("locating") as progress:
        progress(0, 1)
        pose = svc(reference, cloud, out, settings, prefer_angle, camera, frame,
                   reference_room_light)
    _show(pose, out, frame is not None)


def _show(pose, out: Path, framed: bool) -> None:
    """The located pose as a table."""
    b, s = pose.best, pose.second
    own = "" if pose.turn_tolerance_deg is None else f" and {pose.turn_tolerance_deg:g}°"
    table = Table(title=f"part pose → {out}", show_header=False)
    table.add_row("position, mm", f"x {b.x_mm:.3f}, y {b.y_mm:.3f}, z {b.z_mm:.3f}")
    table.add_row("turn about z", f"{b.angle_deg:.3f}°")
    table.add_row("uncertainty", f"1σ {b.rim_sigma_mm:.3f} mm at the part's rim, "
                                 f"{b.turn_sigma_deg:.3f}° (2σ within {pose.tolerance[0]:g} "
                                 f"mm{own}, 3σ of the turn "
                                 f"within {pose.tolerance[1]:g}°)")
    table.add_row("fit", f"fitness {b.fitness:.1%}, coverage {b.coverage:.1%}, inlier RMSE "
                         f"{b.rmse_mm:.3f} mm")
    table.add_row("edges", f"{b.edges} samples, 1σ {b.sigma_mm:.3f} mm, {b.sigma_deg:.3f}°"
                  if b.edges else "not used")
    if framed:
        table.add_row("room-light edges", f"{b.image_edges} points, 1σ {b.image_sigma_mm:.4f} "
                      f"mm, {b.image_sigma_deg:.4f}°" if b.image_edges else b.image_note)
    table.add_row("second best", "none" if s is None else s.describe())
    table.add_row("table", "not found" if pose.table_z_mm is None
                  else f"z {pose.table_z_mm:.3f} mm")
    table.add_row("points", f"{pose.points:,} above the table, {pose.seconds:.2f} s")
    console.print(table)
