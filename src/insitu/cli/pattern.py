"""``insitu pattern show``: what a pattern file or spec will mark — fills, stroke areas,
lines and outlines, size in mm, the units chosen and the loader's remarks — without a cloud."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.table import Table
from rich.text import Text

from insitu.cli.common import bounded, check_output, console, fail, one_line_errors
from insitu.patterns.dxf import FILL_MODES
from insitu.patterns.load import sources_help
from insitu.patterns.vector import BEAM_MM, PAINT_MODES

app = typer.Typer(help="Patterns: show what one will mark.", no_args_is_help=True,
                  add_completion=False)
# preview colours (BGR): fills, open lines, closed outlines, a code's quiet zone
FILL, LINE, OUTLINE, FRAME = (60, 60, 60), (200, 90, 0), (0, 0, 220), (0, 170, 0)


def preview(pattern, size_px: int = 800, margin_px: int = 20) -> np.ndarray:
    """(H, W, 3) uint8 BGR picture of ``pattern``: fills dark gray, open lines blue, closed
    outlines red, a code's quiet-zone frame green; y up, 1 mm = the same pixels both ways."""
    import cv2

    x0, y0, x1, y1 = pattern.bounds()
    s = (size_px - 2 * margin_px) / max(x1 - x0, y1 - y0, 1e-9)
    w, h = (int(np.ceil(d * s)) + 2 * margin_px for d in (x1 - x0, y1 - y0))
    img = np.full((h, w, 3), 255, np.uint8)

    def px(p):
        q = np.column_stack([(p[:, 0] - x0) * s + margin_px, (y1 - p[:, 1]) * s + margin_px])
        return np.round(q * 16).astype(np.int32)

    if pattern.contours:
        cv2.fillPoly(img, [px(c) for c in pattern.contours], FILL, cv2.LINE_AA, 4)
    for p in pattern.paths:
        closed = len(p) > 2 and np.allclose(p[0], p[-1])
        cv2.polylines(img, [px(p)], False, OUTLINE if closed else LINE, 1, cv2.LINE_AA, 4)
    if pattern.frame is not None:
        cv2.polylines(img, [px(pattern.frame)], True, FRAME, 1, cv2.LINE_AA, 4)
    return img


def _render(spec: str, fields: list[str], serial: int) -> str:
    """``spec`` with its variable data rendered for a preview (serial ``serial``, now)."""
    from insitu.patterns.fields import Variables, parse_fields, render_spec

    return render_spec(spec, Variables(serial, parse_fields(fields)))


@app.command("show")
@one_line_errors
def show(
    spec: Annotated[str, typer.Argument(help=f"A file or spec: {sources_help()}.")],
    out: Annotated[Path | None, typer.Option("-o", "--output",
                                             help="Preview picture to write (.png).")] = None,
    fill: Annotated[str, typer.Option(help="A DXF's closed outlines: auto, all or "
                                           "none.")] = "auto",
    beam: Annotated[float, typer.Option(
        callback=bounded("length_mm"), help="Beam width, mm: strokes at least this wide "
                                            "are areas.")] = BEAM_MM,
    paint: Annotated[str, typer.Option(help="An SVG's shaded paints (gradients, patterns, "
                                            "opacity, masks): threshold (marked where darker "
                                            "than 50 %) or dither (dots).")] = "threshold",
    fields: Annotated[list[str] | None, typer.Option(
        "--var", metavar="NAME=VALUE", help="A value for {NAME} in the text.")] = None,
    serial: Annotated[int, typer.Option(help="The serial {serial} is shown with "
                                             "(a preview: no counter is read).")] = 1,
) -> None:
    """Load a pattern as insitu mark would (at its own size) and say what will be marked:
    filled area, lines, closed outlines, size in mm, units chosen, remarks. -o writes a
    preview: fills gray, lines blue, outlines red, a code's quiet zone green. A text with
    variable data ({serial}, {date}, --var values) is shown rendered as a preview."""
    from insitu.formats.atomic import atomic_write_bytes
    from insitu.patterns import load_pattern

    if fill not in FILL_MODES:
        fail(f"--fill {fill!r}: expected one of {', '.join(FILL_MODES)}")
    if paint not in PAINT_MODES:
        fail(f"--paint {paint!r}: expected one of {', '.join(PAINT_MODES)}")
    if out is not None:
        check_output(out, ".png")
    rendered = _render(spec, fields or [], serial)
    p = load_pattern(rendered, fill=fill, beam=beam, paint=paint)
    table = _table(p, beam)
    if rendered != spec:
        table.add_row("preview", f"{rendered} (variable data; serial {serial} as an "
                                 "example)")
    console.print(table)
    if out is not None:
        import cv2

        ok, buf = cv2.imencode(".png", preview(p))
        if not ok:
            fail(f"{out}: OpenCV could not encode the preview")
        atomic_write_bytes(out, buf.tobytes())
        console.print(f"preview → {out}")


def _table(p, beam: float) -> Table:
    """What ``p`` will mark: size, fills, lines, its code, stroke widths, the loader's notes."""
    import shapely

    closed = sum(1 for q in p.paths if len(q) > 2 and np.allclose(q[0], q[-1]))
    lines = len(p.paths) - closed
    length = sum(float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum()) for q in p.paths)
    (w, h), (x0, y0, _, _) = p.size, p.bounds()
    table = Table(title=f"pattern {p.name}", show_header=False)
    table.add_row("size", f"{w:.4g} × {h:.4g} mm (from {x0:.4g}, {y0:.4g})")
    table.add_row("fills", f"{len(p.contours):,} contours, {shapely.area(p.to_shapely()):.4g} "
                           "mm² (hatched when marked)")
    table.add_row("lines", f"{lines:,} open, {closed:,} closed outlines, {length:.4g} mm")
    if p.code is not None:
        c = p.code
        table.add_row("code", f"{c.symbology} {c.cols}×{c.rows} modules, quiet zone {c.quiet}, "
                              f"encodes {c.text!r}")
    if p.stroke_widths:
        table.add_row("strokes", ", ".join(f"{x:.3g}" for x in p.stroke_widths[:8])
                      + (" …" if len(p.stroke_widths) > 8 else "") + f" mm wide (beam {beam:g})")
    for note in p.notes:
        table.add_row(Text("warning", "yellow") if note.startswith("warning:") else "loaded",
                      note.removeprefix("warning: "))
    return table


def standalone() -> None:
    """Run ``insitu pattern …`` under a root like :mod:`insitu.cli.main`'s (its one-line
    usage errors and exit codes) that holds only this group."""
    import sys

    from insitu.cli.common import OneLineUsage, err_console, tagged

    root = typer.Typer(cls=OneLineUsage, no_args_is_help=True, pretty_exceptions_enable=False,
                       add_completion=False, rich_markup_mode="markdown")
    root.add_typer(app, name="pattern")
    try:
        root(prog_name="insitu")
    except KeyboardInterrupt:
        err_console.print(tagged("error:", "bold red", "interrupted"))
        sys.exit(130)
