"""``insitu recipe``: make, extend and show a production recipe (what ``insitu produce`` and
``insitu mark --recipe`` mark on every part, in the part's own frame)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table
from rich.text import Text

from insitu.cli.common import bounded, check_output, console, fail, one_line_errors
from insitu.marking.modes import PROJECTIONS
from insitu.patterns.load import sources_help
from insitu.patterns.vector import BEAM_MM

app = typer.Typer(help="Production recipes: the part's reference, the patterns placed on it "
                       "(part frame), scan, locate and serial settings.",
                  no_args_is_help=True, rich_markup_mode="markdown")

RecipeArg = Annotated[Path, typer.Argument(metavar="RECIPE.json", help="Recipe file.")]
Pattern = Annotated[str, typer.Option(help=f"A file or spec: {sources_help()}.")]
At = Annotated[tuple[float, float], typer.Option(
    metavar="X Y", callback=bounded("position_mm"),
    help="Centre of the pattern X Y, mm, in the part's frame (the reference's).")]
Width = Annotated[float | None, typer.Option(
    callback=bounded("length_mm"), help="Width of the pattern, mm (a code's without its quiet "
                                        "zone; default: the size it loads at, kept in the "
                                        "recipe).")]
Rotate = Annotated[float, typer.Option(callback=bounded("angle_deg"),
                                       help="Rotation, degrees CCW about +z, part frame.")]
Mode = Annotated[str, typer.Option(help="; ".join(f"{k}: {m.description}" for k, m in
                                                  PROJECTIONS.items()) + ".")]
Hatch = Annotated[float | None, typer.Option(callback=bounded("length_mm"),
                                             help="Hatch spacing, mm (default: outlines; "
                                                  "a code along its modules).")]
HatchAngle = Annotated[float, typer.Option(callback=bounded("angle_deg"),
                                           help="Hatch direction, degrees from the part's +x.")]
Beam = Annotated[float, typer.Option(callback=bounded("length_mm"), help="Beam width, mm.")]


def _placement(pattern, at, width, rotate, mode, hatch, hatch_angle, beam):
    """The placement, its pattern loaded once to refuse a bad one now (part frame)."""
    from insitu.marking import Placement
    from insitu.marking.modes import projection_mode
    from insitu.patterns.fields import Variables
    from insitu.patterns.load import is_spec
    from insitu.services.serials import render_placement

    projection_mode(mode)
    p = Placement(pattern, at, width, rotate, mode, hatch, hatch_angle, beam_mm=beam)
    if not is_spec(pattern):
        p = replace(p, pattern=str(Path(pattern).absolute()))
    placed = render_placement(p, Variables(1)).placed()    # a template renders, it loads
    return p if width is not None else replace(p, width_mm=placed.mark_width)


def read(path: Path):
    """The recipe at ``path`` (FormatError naming the field)."""
    from insitu.formats.recipe import read_recipe
    from insitu.marking import Placement

    return read_recipe(path, Placement, PROJECTIONS)


Reference = Annotated[Path, typer.Argument(
    metavar="REFERENCE", help="The part in its own frame: a mesh (.stl, .obj, .ply with faces) "
                              "or the cloud of a first scan (.ply).")]
Output = Annotated[Path, typer.Option("-o", "--output", help="Recipe to write (.json).")]
Workpiece = Annotated[str | None, typer.Option(
    help="Simulated rig: the part on the table (a catalogue name or mesh).")]
Region = Annotated[tuple[float, float, float, float] | None, typer.Option(
    metavar="X0 X1 Y0 Y1", callback=bounded("position_mm"),
    help="Scan region, world mm (default: where the part lies, grown by --margin; a real rig "
         "needs one).")]
Margin = Annotated[float, typer.Option(callback=bounded("length_mm"),
                                       help="Margin around the part, mm.")]
Spacing = Annotated[float, typer.Option(callback=bounded("spacing_mm"),
                                        help="Scan line spacing, mm (locating pins a part by "
                                             "the edges the lines cross).")]
Cross = Annotated[bool, typer.Option(
    help="Scan each part twice over: lines along y, then a crossed pass at 45° to x, so every "
         "edge is crossed whatever the part's turn (Method 2 needs a height calibration "
         "recorded with crossed lines).")]
CrossSpacing = Annotated[float, typer.Option(
    callback=bounded("spacing_mm"),
    help="The crossed pass's line spacing, mm (it only has to cross the edges the first pass "
         "runs along, so it may be coarser).")]
SecondLook = Annotated[bool, typer.Option(
    help="With --no-cross: when the lines along y leave a part's pose unheld (its edges run "
         "along them), scan it again crossed over where it lies.")]
Power = Annotated[float, typer.Option(callback=bounded("power_pct"),
                                      help="Laser power, % of full.")]
Frequency = Annotated[float, typer.Option(callback=bounded("frequency_khz"),
                                          help="Pulse frequency, kHz.")]
Speed = Annotated[float, typer.Option(callback=bounded("mark_speed_mm_s"),
                                      help="Mark speed, mm/s.")]
PreferAngle = Annotated[tuple[float, float] | None, typer.Option(
    metavar="LO HI", callback=bounded("angle_deg"),
    help="A symmetric part: keep the turn about z within LO … HI degrees (default: refuse an "
         "ambiguous part).")]
Counter = Annotated[Path | None, typer.Option(
    help="Serial counter for {serial} (default: serial.counter.json beside the recipe).")]
SerialStart = Annotated[int | None, typer.Option(
    help="Create the counter with this first serial when it does not exist.")]
Fields = Annotated[list[str] | None, typer.Option(
    "--var", metavar="NAME=VALUE", help="A value for {NAME} in the pattern's text.")]
ReferenceRoomLight = Annotated[Path | None, typer.Option(
    "--reference-room-light", metavar="FRAME.png",
    help="A scan REFERENCE's room-light frame (insitu scan --room-light when it was scanned; "
         "needs --height-cal): its outline is fitted there and checked now.")]
HeightCal = Annotated[Path | None, typer.Option(
    "--height-cal", help="The height calibration the scan REFERENCE was measured with (its "
                         "camera places the frame's edges).")]
Tolerance = Annotated[float, typer.Option(
    metavar="MM", callback=bounded("tolerance_mm"),
    help="Mark a part only when its pose is known to 2σ within this at its rim, mm.")]
TurnBound = Annotated[float, typer.Option(
    "--turn-bound", metavar="DEG", callback=bounded("turn_bound_deg"),
    help="And its turn to 3σ within this, degrees.")]
TurnTolerance = Annotated[float | None, typer.Option(
    "--turn-tolerance", metavar="DEG", callback=bounded("turn_bound_deg"),
    help="And its turn to 2σ within this, degrees (the marks' own angle tolerance). "
         "Default: none, the rim's tolerance and --turn-bound decide.")]

LinesPerFrame = Annotated[str | None, typer.Option(
    "--lines-per-frame", metavar="auto|K",
    help="Scan each part with several lines in one exposure: K, or auto (as insitu scan "
         "--lines-per-frame). Default: one line a frame.")]


@app.command("new")
@one_line_errors
def new(reference: Reference, pattern: Pattern, at: At, out: Output, width: Width = None,
        rotate: Rotate = 0.0, mode: Mode = "planar", hatch: Hatch = None,
        hatch_angle: HatchAngle = 0.0, beam: Beam = BEAM_MM, workpiece: Workpiece = None,
        region: Region = None, margin: Margin = 5.0, spacing: Spacing = 0.25,
        cross: Cross = True, cross_spacing: CrossSpacing = 0.5, second_look: SecondLook = True,
        power: Power = 30.0, frequency: Frequency = 20.0, speed: Speed = 500.0,
        prefer_angle: PreferAngle = None, counter: Counter = None,
        serial_start: SerialStart = None, fields: Fields = None,
        reference_room_light: ReferenceRoomLight = None, height_cal: HeightCal = None,
        tolerance: Tolerance = 0.05, turn_bound_deg: TurnBound = 0.1,
        turn_tolerance: TurnTolerance = None, lines_per_frame: LinesPerFrame = None) -> None:
    """Write a recipe: the part's REFERENCE and one pattern placed on it (add more with
    'insitu recipe add'). Positions and turns are in the reference's frame; each part of a
    run is located and the placements moved where it lies. A scan REFERENCE is checked
    first: how much of its outline its room-light frame and its lines show, how well lines
    and circles fit it."""
    from insitu.formats.recipe import Recipe, RecipeScan, reference_kind, write_recipe
    from insitu.patterns.fields import parse_fields
    from insitu.reconstruct.packing import lines_per_frame as per_frame

    check_output(out, ".json")
    per_line = per_frame(lines_per_frame)
    kind = reference_kind(reference)
    check_reference(reference, kind, reference_room_light, height_cal,
                    (tolerance, turn_bound_deg))
    recipe = Recipe(
        reference=reference.absolute(), reference_kind=kind,
        placements=(_placement(pattern, at, width, rotate, mode, hatch, hatch_angle, beam),),
        laser={"power_pct": power, "frequency_khz": frequency, "mark_speed_mm_s": speed,
               "jump_speed_mm_s": 3000.0},
        scan=RecipeScan(region, margin, spacing, cross=cross, cross_spacing_mm=cross_spacing,
                        second_look=second_look, lines_per_frame=per_line),
        prefer_angle_deg=prefer_angle,
        counter=None if counter is None else counter.absolute(), serial_start=serial_start,
        fields=parse_fields(fields or []), workpiece=workpiece,
        reference_room_light=(None if reference_room_light is None
                              else reference_room_light.absolute()),
        tolerance=(tolerance, turn_bound_deg), turn_tolerance_deg=turn_tolerance)
    write_recipe(out, recipe)
    console.print(f"wrote {out}: reference {reference} ({kind}), 1 placement", highlight=False)


def check_reference(reference: Path, kind: str, room_light: Path | None,
                    height_cal: Path | None, tolerance: tuple[float, float] = (0.05, 0.1)
                    ) -> None:
    """A table of what the reference gives locating (a mesh's exact outline, or a scan's
    top coverage, :mod:`insitu.services.reference_check`, and its outline fitted from its
    room-light frame, :func:`insitu.services.reference_outline.outline_findings`), warnings
    in yellow; ConfigError when the scan cannot vouch for the parts located against it."""
    from insitu.errors import ConfigError
    from insitu.formats.pointcloud import read_ply
    from insitu.services.reference_check import check_reference as top_coverage
    from insitu.services.reference_outline import outline_findings, scan_reference

    table = Table(title=f"reference {reference.name}", show_header=False)
    if kind == "mesh":
        table.add_row("kind", "CAD mesh: its outline exact")
        console.print(table)
        return
    cloud = read_ply(reference)
    cover = top_coverage(cloud.points, cloud.attributes.get("line"))
    if cover.level == "refused":
        raise ConfigError(f"{reference}: {cover.text}")
    ref = scan_reference(reference, room_light, height_cal)
    table.add_row("kind", f"a scan: {len(ref.points):,} points above the table")
    table.add_row(Text("coverage", "yellow") if cover.level == "warning" else "coverage",
                  cover.text)
    for level, label, text in outline_findings(ref, tolerance):
        table.add_row(Text(label, "yellow") if level == "warning" else label, text)
    console.print(table)


@app.command("add")
@one_line_errors
def add(recipe_path: RecipeArg, pattern: Pattern, at: At, width: Width = None,
        rotate: Rotate = 0.0, mode: Mode = "planar", hatch: Hatch = None,
        hatch_angle: HatchAngle = 0.0, beam: Beam = BEAM_MM) -> None:
    """Add one more pattern to a recipe (part frame); every part's job marks them all."""
    from insitu.formats.recipe import write_recipe

    recipe = read(recipe_path)
    p = _placement(pattern, at, width, rotate, mode, hatch, hatch_angle, beam)
    write_recipe(recipe_path, replace(recipe, placements=recipe.placements + (p,)))
    console.print(f"wrote {recipe_path}: {len(recipe.placements) + 1} placements",
                  highlight=False)


@app.command("show")
@one_line_errors
def show(recipe_path: RecipeArg) -> None:
    """What a recipe holds: the reference, each placement, scan, laser, locate and serials."""
    from insitu.services.serials import counter_next

    r = read(recipe_path)
    table = Table(title=str(recipe_path), show_header=False)
    table.add_row("reference", f"{r.reference} ({r.reference_kind})" + (
        f", its room-light frame {r.reference_room_light}" if r.reference_room_light else ""))
    table.add_row("tolerance", f"a part is marked when its pose is known to 2σ within "
                               f"{r.tolerance[0]:g} mm at its rim and its turn to 3σ "
                               f"within {r.tolerance[1]:g}°" + (
                                   "" if r.turn_tolerance_deg is None else
                                   f", to 2σ within {r.turn_tolerance_deg:g}°"))
    if r.workpiece:
        table.add_row("simulated part", r.workpiece)
    for i, p in enumerate(r.placements, 1):
        width = "its own size" if p.width_mm is None else f"{p.width_mm:g} mm"
        table.add_row(f"placement {i}", f"{p.pattern} at ({p.at_mm[0]:g}, {p.at_mm[1]:g}), "
                                        f"{width}, {p.rotate_deg:g}°, {p.mode}")
    s = r.scan
    region = ("where the part lies + {:g} mm".format(s.margin_mm) if s.region is None
              else "{:g} … {:g} × {:g} … {:g} mm".format(*s.region))
    table.add_row("scan", f"{region}, lines {s.spacing_mm:g} mm apart" + (
        f", then a crossed pass {s.cross_spacing_mm or s.spacing_mm:g} mm apart" if s.cross
        else ""))
    las = r.laser
    table.add_row("laser", f"{las['power_pct']:g} %, {las['frequency_khz']:g} kHz, mark "
                           f"{las['mark_speed_mm_s']:g} mm/s")
    table.add_row("symmetry", "refuse an ambiguous part" if r.prefer_angle_deg is None else
                  "keep the turn within {:g} … {:g}°".format(*r.prefer_angle_deg))
    nxt = counter_next(r.counter)
    table.add_row("serials", f"{r.counter}: next {nxt}" if nxt is not None else
                  f"{r.counter} (created at the first part"
                  + (f", first serial {r.serial_start})" if r.serial_start is not None
                     else "; none yet: set --serial-start or insitu serial set)"))
    console.print(table)


def check_recipe_options(**given) -> None:
    """One line for `mark --recipe` options that the recipe already holds."""
    bad = [k for k, v in given.items() if v]
    if bad:
        fail(f"--recipe holds the placements and laser: drop {', '.join(bad)}")


def mark_recipe(recipe_path: Path, cloud: Path, out: Path, run: bool, preview: bool,
                inspect: Path | None, rig: Path | None, field: Path | None, workpiece: str,
                seed: int) -> None:
    """``insitu mark --recipe``: locate the recipe's part in ``cloud``, plan every placement
    where it lies as one job at ``out`` (the serial issued from the recipe's counter), show
    it, and with ``run`` mark it."""
    from insitu.cli.common import progress_bar, warn
    from insitu.cli.job import run_on_station
    from insitu.cli.mark import record_rows
    from insitu.formats.pointcloud import read_ply
    from insitu.services import production
    from insitu.services.locate import recipe_locator
    from insitu.services.station import connect

    if inspect is not None:
        check_output(inspect, ".png")
    if (preview or inspect is not None) and not run:
        fail("--preview and --inspect go with --run")
    r = read(recipe_path)
    measured = read_ply(cloud)
    with connect(rig, r.workpiece or workpiece, seed, field=field) as station:
        with progress_bar("locating") as progress:
            progress(0, 1)
            located = recipe_locator(r)(measured)
        with progress_bar("projecting") as progress:
            progress(0, 1)
            planned = production.plan_recipe(station, r, measured, located, out, cloud,
                                             marking=run)
        x, y, a = located.pose()
        table = Table(title=f"mark job → {out}", show_header=False)
        table.add_row("part located", f"x {x:.3f} mm, y {y:.3f} mm, turned {a:.3f}° "
                                      f"(fitness {located.fitness:.3f}, RMSE "
                                      f"{located.rmse_mm:.3f} mm)")
        for i, p in enumerate(r.placements, 1):
            w = p.in_world(located.T_world_part)
            table.add_row(f"placement {i}", f"{p.pattern} at ({w.at_mm[0]:.3f}, "
                                            f"{w.at_mm[1]:.3f}) mm, {w.rotate_deg:.2f}°")
        for f in {f: None for o in planned.outcomes for f in o.findings}:
            if f.level == "warning" and f.check == "rig":
                warn(f.text)
            elif f.level == "warning":
                table.add_row(Text("warning", "yellow"), f.text)
        record_rows(table, planned.record)
        table.add_row("marks", f"{len(planned.job.paths):,} paths")
        console.print(table)
        if run:
            run_on_station(station, planned.job, out, False, preview, inspect,
                           read=([o.plan for o in planned.outcomes], measured))
