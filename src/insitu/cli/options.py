"""The options the commands share, declared once (name, type, help, bounds): the rig and the
simulated part, marking runs, scan passes, and the options of ``insitu mark``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from insitu.cli.common import bounded, bounded_each, fail, progress_bar
from insitu.formats.validation import one_of
from insitu.marking.modes import PROJECTIONS
from insitu.patterns.load import sources_help
from insitu.reconstruct.height_models import HEIGHT_MODELS

# options of every command that marks on the rig (``insitu job run``, ``insitu mark --run``)
Resume = Annotated[bool, typer.Option(help="Continue an interrupted job: the paths its "
                                           "journal does not record as done.")]
Restart = Annotated[bool, typer.Option(help="Mark an interrupted job again from its first "
                                            "path (the journal keeps the earlier runs).")]
CutPath = Annotated[str | None, typer.Option(
    help="With --resume, the path started but not confirmed: remark (mark it again whole), "
         "skip (leave it as it is) or continue (from where the board reported it stopped).")]
Preview = Annotated[bool, typer.Option(help="First draw the outline with the pilot laser.")]
Inspect = Annotated[Path | None, typer.Option(help="Write the camera's image of the marked "
                                                   "part (.png).")]
Rig = Annotated[Path | None, typer.Option(help="Rig file (default: the simulated rig).")]
Field = Annotated[Path | None, typer.Option(help="Field correction (FIELD.json) to apply "
                                                 "(default: the rig file's).")]
Workpiece = Annotated[str, typer.Option(help="Simulated rig: the part on the table.")]
Seed = Annotated[int, typer.Option(help="Simulated rig: seed.", callback=bounded("seed"))]
PartPose = Annotated[tuple[float, float, float], typer.Option(
    "--pose", metavar="X Y ANGLE_DEG",
    callback=bounded_each("position_mm", "position_mm", "angle_deg"),
    help="Simulated rig: where the part lies — its origin at X Y, mm, turned ANGLE_DEG "
         "about +z (a cloud measured at another pose is another placement).")]
CrossScan = Annotated[bool, typer.Option(
    help="Scan a second, crossed pass over the same region (lines at 45° to x), so edges "
         "that run along the first pass's lines are measured too; with a height calibration "
         "it must have been recorded with crossed lines.")]
CrossSpacing = Annotated[float | None, typer.Option(
    callback=bounded("spacing_mm"),
    help="With --cross: the crossed lines' spacing, mm (default: --spacing; the crossed "
         "pass only has to cross the edges, so it may be coarser).")]
# how a scan's heights are measured (``insitu scan``, ``insitu depth``)
HeightCal = Annotated[Path | None, typer.Option(
    "--height-cal", help="Height calibration: a recorded folder or a file from 'insitu "
                         "calibrate height' (a live scan with --rig: default the rig "
                         "file's).")]
Method = Annotated[str | None, typer.Option(
    help="plane: light-plane intersection only (Method 1); height: with the height "
         "calibration (Method 2, the default when --height-cal is given).")]
HeightModel = Annotated[str | None, typer.Option(
    help="With --method height: " + " or ".join(f"{k} ({m.description})" for k, m in
                                                 HEIGHT_MODELS.items()) + ".")]
RecordCross = Annotated[bool | None, typer.Option(
    "--cross/--no-cross",
    help="Scan: a second, crossed pass (lines at 45° to x; default off). Height calibration: "
         "also the crossed lines a crossed scan needs (default on).")]
Paint = Annotated[str, typer.Option(
    "--paint", help="An SVG's shaded paints (gradients, patterns, opacity, masks): threshold "
                    "(marked where darker than 50 %) or dither (dots).")]
Force = Annotated[bool, typer.Option(help="Write the job even when a code would not decode "
                                          "from the planned marks.")]

# where and how ``insitu mark`` places its pattern
PatternSpec = Annotated[str | None, typer.Option(
    "--pattern", help=f"A file or spec: {sources_help()}. Required without --recipe.")]
At = Annotated[tuple[float, float] | None, typer.Option(
    "--at", metavar="X Y", callback=bounded("position_mm"),
    help="Centre of the pattern X Y, mm, world frame (the part's with --part-pose). "
         "Required without --recipe.")]
Width = Annotated[float | None, typer.Option(
    "--width", callback=bounded("length_mm"),
    help="Width of the pattern, mm (before --rotate; a code's without its quiet zone; "
         "default: the size it loads at, e.g. a code's ;module=).")]
Rotate = Annotated[float, typer.Option(
    "--rotate", callback=bounded("angle_deg"),
    help="Rotation, degrees CCW about +z (from the part's x axis with --part-pose).")]
PosePath = Annotated[Path | None, typer.Option(
    "--part-pose", help="POSE.json of `insitu locate`: --at, --rotate and --hatch-angle are "
                        "then in the part's own frame, moved to where the part lies.")]
Mode = Annotated[str, typer.Option(
    "--mode", help="; ".join(f"{k}: {m.description}" for k, m in PROJECTIONS.items()) + ".")]
Hatch = Annotated[float | None, typer.Option(
    "--hatch", callback=bounded("length_mm"),
    help="Fill filled regions with hatch lines this far apart, mm (default: outlines only).")]
HatchAngle = Annotated[float, typer.Option(
    "--hatch-angle", callback=bounded("angle_deg"), help="Hatch direction, degrees from +x.")]
Cross = Annotated[bool, typer.Option("--cross/--no-cross",
                                     help="Cross-hatch (a second hatch at +90°).")]
Fill = Annotated[str, typer.Option(
    "--fill", help="A DXF's closed outlines: auto (fills where the file has hatches, solids, "
                   "wide polylines, text; other outlines as lines), all (fill every closed "
                   "outline), none (outlines only).")]
Beam = Annotated[float, typer.Option(
    "--beam", callback=bounded("length_mm"),
    help="Beam width, mm: strokes at least this wide are marked as their area, thinner ones "
         "as lines; a code's default hatch is no coarser.")]

# the laser: a pen and the settings that override it
PenName = Annotated[str | None, typer.Option(
    "--pen", help="The pen (named laser set: power, frequency, speeds, passes, delays, "
                  "wobble) of --pens to mark with (default: its default pen).")]
PensFile = Annotated[Path | None, typer.Option(
    "--pens", metavar="PENS.json", help="Pens file (insitu-pens/1) or a project "
    "(.insitu.json) whose pens --pen picks from (default: the built-in mark, fine, deep, "
    "bold).")]
Power = Annotated[float | None, typer.Option(
    "--power", callback=bounded("power_pct"),
    help="Laser power, % of full (default: the pen's, else 30).")]
Frequency = Annotated[float | None, typer.Option(
    "--frequency", callback=bounded("frequency_khz"),
    help="Pulse frequency, kHz (default: the pen's, else 20).")]
Speed = Annotated[float | None, typer.Option(
    "--speed", callback=bounded("mark_speed_mm_s"),
    help="Mark speed, mm/s (default: the pen's, else 500).")]
JumpSpeed = Annotated[float | None, typer.Option(
    "--jump-speed", callback=bounded("jump_speed_mm_s"),
    help="Jump speed, mm/s (default: the pen's, else 3000).")]

# variable data
Vars = Annotated[list[str] | None, typer.Option(
    "--var", metavar="NAME=VALUE", help="A value for {NAME} in the pattern's text (again for "
    "more fields); {serial}, {date}, {time} are built in.")]
CounterPath = Annotated[Path | None, typer.Option(
    "--counter", help="Serial counter for {serial} (default: serial.counter.json beside the "
                      "job).")]
SerialStart = Annotated[int | None, typer.Option(
    "--serial-start", help="Create the serial counter, its first serial this.")]


def rig_height_calibration(rig: Path) -> Path | None:
    """The height calibration the rig file names (None: none): ``--height-cal``'s default on
    a real rig."""
    from insitu.formats.json_file import load_json_model
    from insitu.formats.rig import RigConfig

    cfg = load_json_model(rig, RigConfig)
    return cfg.resolve(cfg.height_calibration)


def scan_calibration(method: str | None, height_cal: Path | None, height_model: str | None):
    """The height calibration a scan uses (None: Method 1), its options (:data:`Method`,
    :data:`HeightCal`, :data:`HeightModel`) checked."""
    from insitu import services

    method = method or ("height" if height_cal is not None else "plane")
    if method not in ("plane", "height"):
        fail(f"--method {method!r}: expected 'plane' or 'height'")
    if method == "height" and height_cal is None:
        fail("--method height needs --height-cal HCAL")
    if height_model is not None and height_model not in HEIGHT_MODELS:
        fail(f"--height-model {height_model!r}: expected {one_of(HEIGHT_MODELS)}")
    if method != "height":
        return None
    with progress_bar("height calibration") as progress:
        return services.load_height_calibration(height_cal, progress)
