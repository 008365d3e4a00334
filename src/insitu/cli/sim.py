"""``insitu sim record KIND -o REC``: recorded sequences from the simulated rig."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from insitu.cli.common import (
    bounded,
    check_output,
    console,
    fail,
    one_line_errors,
    parse_heights,
    progress_bar,
)
from insitu.cli.options import PartPose, RecordCross
from insitu.formats.project import SIM_BINNING
from insitu.services import record
from insitu.sim.pocket_plate import PLATES
from insitu.sim.workpieces import WORKPIECES

app = typer.Typer(help="The simulated rig.", no_args_is_help=True,
                 rich_markup_mode="markdown")


Kind = Annotated[str, typer.Argument(help="scan | height-calibration | field-calibration | "
                                           "camera-calibration")]
Output = Annotated[Path, typer.Option("-o", "--output",
                                      help="Folder to write (replaced if it exists).")]
Part = Annotated[str, typer.Option(help=f"For a scan: {', '.join(WORKPIECES)}, "
                                        f"{', '.join(PLATES)} (a stainless blank with four "
                                        "2 × 2 mm pockets 0.05 … 0.5 mm deep at x = −7.5, "
                                        "−2.5, 2.5, 7.5 mm; truth.json gives each one's true "
                                        "depth) or a mesh file (STL/PLY/OBJ).")]
Spacing = Annotated[float, typer.Option(callback=bounded("spacing_mm"),
                                        help="Scan line spacing, mm.")]
Region = Annotated[tuple[float, float, float, float] | None, typer.Option(
    metavar="X0 X1 Y0 Y1", callback=bounded("position_mm"),
    help="Scan region X0 X1 Y0 Y1, mm (default: the part).")]
Seed = Annotated[int, typer.Option(callback=bounded("seed"),
                                   help="Seed of the simulated rig and its noise.")]
Binning = Annotated[int, typer.Option(help="Divide the 2448×2048 image by this (1, 2, 4, 8).")]
Views = Annotated[int, typer.Option(callback=bounded("count"),
                                    help="Camera calibration: checkerboard views.")]
Grid = Annotated[int, typer.Option(callback=bounded("count"),
                                   help="Field calibration: spots per side.")]
Marked = Annotated[bool, typer.Option(help="Field calibration: mark circles on the plate and "
                                           "image them instead of pilot spots.")]
Heights = Annotated[str, typer.Option(
    metavar="Z1,Z2,...",
    help="Field calibration: plate heights, mm, comma-separated. Two or more (e.g. 0,20) "
         "record the spots `insitu calibrate camera` needs to re-estimate the camera's pose "
         "after it moved.")]
Alignment = Annotated[bool, typer.Option(
    "--axis-lines/--no-axis-lines",
    help="Camera calibration: after the views, the board flat on the plate with the head's x "
         "and y axis lines drawn on it, which give the camera's pose in the scan-head "
         "frame.")]
MovedDeg = Annotated[float, typer.Option(
    callback=bounded("angle_deg"),
    help="Knock the camera after its calibration: turn it by this angle, degrees, about a "
         "random axis (from --seed). sequence.json keeps the operator's calibration of the "
         "old pose; truth.json holds the moved camera.")]
MovedMm = Annotated[float, typer.Option(
    callback=bounded("move_mm"),
    help="Knock the camera after its calibration: move it by this distance, mm, in a random "
         "direction (from --seed).")]
LinesPerFrame = Annotated[str | None, typer.Option(
    "--lines-per-frame", metavar="K|auto",
    help="Scan: K lines drawn in each exposure (frames with `lines`), after survey frames "
         "that bound the heights (auto: as many as those heights allow). Default: one.")]


@app.command("record")
@one_line_errors
def record_cmd(kind: Kind, out: Output, workpiece: Part = "step-block",
               pose: PartPose = (0.0, 0.0, 0.0), spacing: Spacing = 0.5,
               cross: RecordCross = None, region: Region = None, seed: Seed = 0,
               binning: Binning = SIM_BINNING, views: Views = 15, grid: Grid = 21,
               marked: Marked = False, heights: Heights = "0", alignment: Alignment = True,
               camera_moved_deg: MovedDeg = 0.0, camera_moved_mm: MovedMm = 0.0,
               lines_per_frame: LinesPerFrame = None) -> None:
    """Write a recorded sequence (docs/formats.md) from the simulated rig, with truth.json.

    To try the recalibration after a camera move: record and fit a field calibration
    (`insitu calibrate field`), then record spots at two heights with the camera moved
    (`--heights 0,20 --grid 7 --camera-moved-deg 0.5 --camera-moved-mm 2`) and run
    `insitu calibrate camera SPOTS --field FIELD.json -o CAMERA.json`."""
    from insitu.geometry.beams import axis_lines
    from insitu.reconstruct.packing import lines_per_frame as per_frame
    from insitu.services.station import simulated
    from insitu.sim.board import BoardViews
    from insitu.sim.rig import default_rig, move_camera
    from insitu.sim.world import sim_world

    if kind not in record.KINDS:
        fail(f"KIND {kind!r}: expected one of {', '.join(record.KINDS)}")
    if binning not in (1, 2, 4, 8):
        fail(f"--binning {binning}: expected 1, 2, 4 or 8")
    plate_z = parse_heights(heights)
    if plate_z != [0.0] and (kind != "field-calibration" or marked):
        fail(f"--heights {heights}: plate heights are for spot field calibrations only")
    if any(pose) and kind != "scan":
        fail("--pose places the part for a scan; calibrations clear the table")
    if lines_per_frame is not None and kind != "scan":
        fail(f"--lines-per-frame {lines_per_frame}: several lines a frame are for a scan")
    check_output(out)
    rig = default_rig(seed, binning)
    if camera_moved_deg or camera_moved_mm:
        rig = move_camera(rig, camera_moved_deg, camera_moved_mm, seed)
    world = sim_world(workpiece if kind == "scan" else "step-block", rig=rig, seed=seed,
                      pose=pose if kind == "scan" else (0.0, 0.0, 0.0))
    board = (BoardViews(world, views, lines=axis_lines() if alignment else None)
             if kind == "camera-calibration" else None)
    with progress_bar(f"recording {kind}") as progress, simulated(world) as station:
        record.record(station, kind, out, spacing=spacing, region=region, cross=cross,
                      grid=grid, heights=plate_z, marked=marked, next_view=board, views=views,
                      truth=board.truth if board else None, alignment=alignment,
                      progress=progress, lines_per_frame=per_frame(lines_per_frame))
    console.print(f"wrote {out}")


@app.command("export-part")
@one_line_errors
def export_part(
    name: Annotated[str, typer.Argument(help=f"{', '.join(WORKPIECES)}.")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Mesh to write (.stl, .ply or "
                                                             ".obj).")],
) -> None:
    """Write a simulated part's mesh in its own frame (mm; it stands on z = 0): the
    reference `insitu locate` finds it by."""
    from insitu.formats.mesh import write_mesh
    from insitu.sim.workpieces import make_workpiece

    if name not in WORKPIECES:
        fail(f"NAME {name!r}: expected one of {', '.join(WORKPIECES)}")
    part = make_workpiece(name)
    write_mesh(out, part.vertices, part.triangles)
    console.print(f"wrote {out} ({len(part.triangles):,} triangles)", highlight=False)


@app.command("calib")
@one_line_errors
def calib_cmd(
    out: Annotated[Path, typer.Option("-o", "--output", help="Folder for the files (created).")],
    seed: Annotated[int, typer.Option(
        callback=bounded("seed"), help="Seed of the simulated rig.")] = 0,
) -> None:
    """Write the simulated rig's files as its operator knows them: camera.json (calibrated
    camera, with realistic errors), scan-head.json (nominal geometry) and rig.json (with the
    simulated devices' timing, options.sim_timing)."""
    from dataclasses import asdict

    from insitu.formats.calibration import CameraCalibration
    from insitu.formats.json_file import save_json_model
    from insitu.formats.rig import RigConfig, ScanHeadConfig
    from insitu.sim.clock import SimTiming
    from insitu.sim.rig import default_rig

    out.mkdir(parents=True, exist_ok=True)
    rig = default_rig(seed=seed)
    source = [f"simulated rig, seed {seed}"]
    save_json_model(out / "camera.json", CameraCalibration(
        camera=rig.operator.camera.to_dict(), inputs=source,
        notes="the simulated operator's calibration: the true camera plus realistic errors"))
    save_json_model(out / "scan-head.json", ScanHeadConfig(**rig.operator.head.model_dump(),
                                                           inputs=source))
    save_json_model(out / "rig.json", RigConfig(
        camera_calibration="camera.json", scan_head_config="scan-head.json", sim_seed=seed,
        options={"sim_timing": asdict(SimTiming())}))
    console.print(f"wrote {out}/camera.json, scan-head.json, rig.json")
