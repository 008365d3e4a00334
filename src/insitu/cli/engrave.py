"""``insitu engrave``: a pattern engraved to a depth, measured between passes."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from insitu.cli.common import bounded, console, missing, one_line_errors, progress_bar
from insitu.cli.options import (
    At,
    Field,
    PartPose,
    PatternSpec,
    Resume,
    Rig,
    Rotate,
    Seed,
    Width,
    Workpiece,
)

Depth = Annotated[float | None, typer.Option(
    "--depth", callback=bounded("depth_mm"), help="Depth to engrave to, mm (required).")]
RescanEvery = Annotated[int, typer.Option(
    "--rescan-every", callback=bounded("rescan_every"),
    help="Measure the pocket after at most this many passes (sooner when the floor is near).")]
MaterialName = Annotated[str, typer.Option(
    "--material", help="The material (a name of the materials table: stainless-steel, "
                       "anodised-aluminium, beech built in): its pen, hatch and ablation "
                       "constants, where the removal rate starts.")]
MaterialsFile = Annotated[Path | None, typer.Option(
    "--materials", metavar="MATERIALS.json", help="Materials file (insitu-materials/1) "
    "(default: the rig file's options.projection.materials_file, else the built-in table).")]
HeightCal = Annotated[Path | None, typer.Option(
    "--height-cal", help="Height calibration (file or recorded folder) for the depth scans "
                         "(default: the light plane alone).")]
Spacing = Annotated[float, typer.Option(
    "--scan-spacing", callback=bounded("spacing_mm"),
    help="The depth scans' line spacing, mm.")]


@one_line_errors
def engrave(
    cloud: Annotated[Path, typer.Option(help="Measured point cloud (.ply) of the part, "
                                             "before engraving.")],
    out: Annotated[Path, typer.Option("-o", "--output", metavar="REPORT_DIR",
                                      help="Folder of the report (created): the record, "
                                           "each round's job and journal, the pictures.")],
    pattern: PatternSpec = None, at: At = None, width: Width = None, rotate: Rotate = 0.0,
    depth: Depth = None, rescan_every: RescanEvery = 10,
    material: MaterialName = "stainless-steel", materials: MaterialsFile = None,
    height_cal: HeightCal = None, scan_spacing: Spacing = 0.1, resume: Resume = False,
    rig: Rig = None, field: Field = None, workpiece: Workpiece = "blank-stainless",
    seed: Seed = 0, pose: PartPose = (0.0, 0.0, 0.0),
) -> None:
    """Engrave the pattern's filled area, centred at X Y, to --depth on the measured surface:
    layers of hatch with the focus following the floor, and every --rescan-every passes (or
    when the floor is near) a scan of the pocket, a map of the depth still missing per cell,
    and the next passes only where it is. It stops at depth, or when the cells left short
    are ones the camera cannot see past the walls (said in the report; they are never
    over-burnt). The report in REPORT_DIR: depth map, histogram, passes, station time, each
    measurement (engrave.json). A run stopped (ABORT, Ctrl-C, a fault) goes on with
    --resume, which measures the pocket first."""
    from insitu.cli.job import stop_on_signals
    from insitu.formats.pointcloud import read_ply
    from insitu.marking import Placement
    from insitu.services.engrave import EngraveRequest
    from insitu.services.engrave import engrave as run
    from insitu.services.height import load_height_calibration
    from insitu.services.station import connect

    if pattern is None or at is None or depth is None:
        missing("--pattern: missing; expected a word" if pattern is None else
                "--at: missing; expected 2 numbers X Y" if at is None else
                "--depth: missing; expected a number, mm")
    if not out.parent.is_dir():
        raise typer.BadParameter(f"{out}: folder {out.parent} does not exist", param_hint="-o")
    cal = load_height_calibration(height_cal) if height_cal is not None else None
    surface = read_ply(cloud)
    with connect(rig, workpiece, seed, field=field, pose=pose) as station:
        table, source = _materials(materials, station.cfg, material)
        req = EngraveRequest(out, Placement(pattern, tuple(at), width, rotate), surface,
                             depth, rescan_every, material, table, cal, scan_spacing,
                             resume=resume, materials_from=source)
        with stop_on_signals("engraving", f" (insitu engrave ... --resume -o {out} goes on)"), \
                progress_bar("engraving", "steps") as progress:
            outcome = run(station, req, progress=progress,
                          notify=lambda text: console.print(text, highlight=False))
    _summary(outcome, out)


def _materials(given: Path | None, cfg, material: str):
    """(the materials table, where it was read): ``given`` (--materials), else the file the
    rig file ``cfg`` names in ``options.projection.materials_file``, else the built-in table;
    ``material`` checked in it (FormatError naming the file)."""
    from insitu.formats.materials import DEFAULT_MATERIALS, read_materials

    named = cfg.options.get("projection", {}).get("materials_file")
    if given is not None:
        table, source, where = read_materials(given), f"{given} (--materials)", str(given)
    elif named:
        path = cfg.resolve(named)
        table, where = read_materials(path), str(path)
        source = f"{path} (the rig file's options.projection.materials_file)"
    else:
        table, source, where = DEFAULT_MATERIALS, "the built-in table", "--material"
    table.material(material, where)
    return table, source


def _summary(outcome, out: Path) -> None:
    """The outcome's table: how it ended, each measurement, the station's time."""
    from insitu.formats.pens import Pen
    from insitu.services.engrave import station_seconds

    rec = outcome.record
    t = Table(title=f"engraved: {rec.state}", show_header=True)
    for col in ("after round", "passes", "mean depth mm", "± mm", "µm/pass", "at depth",
                "short", "over", "hidden", "not measured"):
        t.add_column(col)
    for m in rec.measures:
        mean = ("–", "–") if m["mean_mm"] is None else (f"{m['mean_mm']:.4f}",
                                                        f"{m['sem_mm']:.4f}")
        t.add_row(str(m["round"]), f"{m['passes_mean']:.1f}", *mean,
                  f"{m['rate_mm'] * 1e3:.2f}", str(m["at_depth"]), str(m["short"]),
                  str(m["over"]), str(m["cells"]["hidden"]), str(m["cells"]["unmeasured"]))
    console.print(t)
    s = station_seconds(rec)
    console.print(f"station time {s['total']:.1f} s (marking {s['marking']:.1f} s, scanning "
                  f"{s['scanning']:.1f} s); {len(rec.rounds)} rounds, {rec.layers} layers",
                  highlight=False)
    fine = [str(k) for k, r in enumerate(rec.rounds, 1) if r.finishing]
    if fine:
        pen = Pen.model_validate(next(r for r in rec.rounds if r.finishing).finish_pen)
        console.print(f"finishing passes in round{'s' * (len(fine) > 1)} {', '.join(fine)}: "
                      f"{pen.name}, {pen.summary()}", highlight=False)
    if rec.outcome and rec.outcome.get("held_cells"):
        console.print(f"{rec.outcome['held_cells']} cells short of the depth cannot be seen "
                      "past the walls: left as they are (engrave.json: held_at_mm)",
                      highlight=False)
    console.print(f"report: {out}/engrave.json, depth-map.png, histogram.png", highlight=False)
