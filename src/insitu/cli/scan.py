"""``insitu scan``: reconstruct a recorded scan, or drive the rig to scan and reconstruct."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import cv2
import typer
from rich.table import Table

from insitu.cli.common import bounded, check_output, console, fail, one_line_errors, progress_bar
from insitu.cli.options import (
    CrossScan,
    CrossSpacing,
    HeightCal,
    HeightModel,
    Method,
    PartPose,
    Rig,
    Seed,
    Workpiece,
    rig_height_calibration,
    scan_calibration,
)
from insitu.formats.atomic import atomic_write_bytes
from insitu.formats.project import SIM_BINNING

Output = Annotated[Path, typer.Option("-o", "--output", help="Point cloud to write (.ply).")]
Replay = Annotated[Path | None, typer.Option(help="Recorded scan folder to reconstruct.")]
Spacing = Annotated[float, typer.Option(callback=bounded("spacing_mm"), help="Line spacing, mm.")]
Region = Annotated[tuple[float, float, float, float] | None, typer.Option(
    metavar="X0 X1 Y0 Y1", callback=bounded("position_mm"),
    help="Region X0 X1 Y0 Y1, mm (default on the simulated rig: the whole part; a real rig "
         "needs one).")]
Binning = Annotated[int, typer.Option(
    callback=bounded("binning"), help="Simulated rig: divide the image size by this.")]
LineSpeed = Annotated[float | None, typer.Option(
    callback=bounded("mark_speed_mm_s"),
    help="How fast the head sweeps each line, mm/s (default: the rig file's).")]
PreviewPng = Annotated[Path | None, typer.Option(
    help="Also write a picture of the cloud (.png): the top view by height, and in the "
         "camera's room-light grey when the scan has it.")]
RoomLight = Annotated[Path | None, typer.Option(
    "--room-light", metavar="FRAME.png",
    help="Also write the camera's frame under the room light, laser off, taken before the "
         "lines (for `insitu locate --room-light`).")]
LinesPerFrame = Annotated[str | None, typer.Option(
    "--lines-per-frame", metavar="auto|K",
    help="Draw several lines in one exposure: K, or auto (as many as the heights a first "
         "sparse frame measures allow); each line's centres only where its band — from the "
         "rig's geometry and the heights — holds them, none where two bands could. Default: "
         "one line a frame.")]
PartHeights = Annotated[tuple[float, float] | None, typer.Option(
    "--part-heights", metavar="LOW HIGH", callback=bounded("position_mm"),
    help="With several lines a frame: the surface's heights LOW … HIGH, mm, when known "
         "(no survey frame; its bands follow them). Replay: instead of its survey frames'.")]


@one_line_errors
def scan(out: Output, replay: Replay = None, height_cal: HeightCal = None,
         method: Method = None, height_model: HeightModel = None, rig: Rig = None,
         workpiece: Workpiece = "step-block", pose: PartPose = (0.0, 0.0, 0.0),
         spacing: Spacing = 0.5, cross: CrossScan = False, cross_spacing: CrossSpacing = None,
         region: Region = None, seed: Seed = 0, binning: Binning = SIM_BINNING,
         line_speed: LineSpeed = None, preview: PreviewPng = None,
         room_light: RoomLight = None, lines_per_frame: LinesPerFrame = None,
         part_heights: PartHeights = None) -> None:
    """Scan a part (or replay a recorded scan: its own lines, crossed or not, one or several
    a frame) and write its point cloud."""
    from insitu import services
    from insitu.reconstruct.packing import lines_per_frame as per_frame
    from insitu.services.station import connect

    check_output(out, ".ply")
    if room_light is not None:
        check_output(room_light, ".png")
    if height_cal is None and rig is not None and replay is None:
        height_cal = rig_height_calibration(rig)
    cal = scan_calibration(method, height_cal, height_model)
    packing = {"heights": _heights(part_heights)}
    with progress_bar("scanning", "lines") as progress:
        if replay is not None:
            result = services.scan_replay(replay, cal, height_model, progress=progress,
                                          **packing)
        else:
            with connect(rig, workpiece, seed, binning, pose=pose) as station:
                result = _live(station, out, spacing=spacing, region=region, height_cal=cal,
                               model=height_model, progress=progress, speed_mm_s=line_speed,
                               cross=cross, cross_spacing=cross_spacing,
                               lines_per_frame=per_frame(lines_per_frame), **packing)
    services.save_cloud(result, out)
    if room_light is not None and result.room_light is not None:
        atomic_write_bytes(room_light, cv2.imencode(".png", result.room_light)[1].tobytes())
    if preview is not None:
        from insitu.reconstruct.preview import save_cloud_picture
        save_cloud_picture(result.cloud, check_output(preview, ".png"), title=out.name)
    console.print(_table(result, out, room_light))


def _heights(part_heights) -> tuple[float, float] | None:
    if part_heights is not None and not part_heights[0] < part_heights[1]:
        fail(f"--part-heights {part_heights[0]:g} {part_heights[1]:g}: expected LOW < HIGH")
    return part_heights


def _table(result, out: Path, room_light: Path | None) -> Table:
    s = result.summary
    table = Table(title=f"scan → {out}", show_header=False)
    table.add_row("method", s.method)
    table.add_row("points", f"{s.points:,} ({s.outliers_removed:,} isolated and "
                            f"{s.unconfirmed_removed:,} unconfirmed by the neighbouring lines "
                            "removed)")
    table.add_row("lines with points", f"{s.frames_with_line} of {s.frames} ({s.coverage:.0%})")
    table.add_row("frames", f"{s.camera_frames}: {s.packing}")
    table.add_row("x range, mm", f"{s.bounds_min[0]:.2f} … {s.bounds_max[0]:.2f}")
    table.add_row("y range, mm", f"{s.bounds_min[1]:.2f} … {s.bounds_max[1]:.2f}")
    table.add_row("z range, mm", f"{s.bounds_min[2]:.2f} … {s.bounds_max[2]:.2f}")
    table.add_row("camera colours", s.ambient)
    if room_light is not None:
        table.add_row("room-light frame", f"→ {room_light}" if result.room_light is not None
                      else f"not written: {s.ambient}")
    table.add_row("time", scan_time_text(s))
    return table


def scan_time_text(s) -> str:
    """The scan's seconds: the station's own (its frames; none for a replay or a real rig),
    the computer's processing CPU — which runs beside the frames, so a station's scan takes
    the longer of the two — and the wall clock's (with the simulator's drawing)."""
    cpu = f"CPU {s.cpu_s:.2f} s (processing)"
    if s.station_s is None:
        return f"{cpu}, wall {s.seconds:.1f} s"
    return (f"station {s.station_s:.2f} s, {cpu}: a cycle of {max(s.station_s, s.cpu_s):.2f} s "
            f"(the slower of the two); wall {s.seconds:.1f} s")


def _live(station, out: Path, **kw):
    """Scan on the station's devices. A device that stops answering ends the scan with the
    laser off; what was measured until then is written beside ``out`` (``*.partial.ply``)."""
    from insitu import services

    try:
        return services.scan_live(station, **kw)
    except services.ScanInterrupted as e:
        if e.partial is None:
            raise
        partial = out.with_name(out.stem + ".partial.ply")
        services.save_cloud(e.partial, partial)
        fail(f"{e}; the {len(e.partial.cloud):,} points measured before it are in {partial}")
