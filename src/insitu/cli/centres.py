"""``insitu centres IMAGE... -o centres.csv [--preview DIR]``: the line-centre extraction on
anyone's images.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
import typer

from insitu.cli.common import check_output, console, one_line_errors
from insitu.errors import InsituError
from insitu.formats import images
from insitu.formats.atomic import atomic_write_bytes, atomic_write_text
from insitu.formats.validation import one_of
from insitu.vision.centres import CENTRE_METHODS, LineCentres, UncertainLine, photo_centres
from insitu.vision.laser_image import PIXEL_BITS

COLUMNS = "file,u,v,peak,width,quality"


def _check_options(method: str, direction: str, channel: str, pixel_bits: int | None) -> None:
    """InsituError (one line) naming an option outside what the command takes."""
    if method not in CENTRE_METHODS:
        raise InsituError(f"--method {method!r}: expected {one_of(CENTRE_METHODS)}")
    if direction not in ("auto", "rows", "cols"):
        raise InsituError(f"--direction {direction!r}: expected 'auto', 'rows' or 'cols'")
    if channel not in ("auto", "r", "g", "b"):
        raise InsituError(f"--channel {channel!r}: expected 'auto', 'r', 'g' or 'b'")
    if pixel_bits is not None and pixel_bits not in PIXEL_BITS:
        raise InsituError(f"--pixel-bits {pixel_bits}: expected "
                          f"{', '.join(map(str, PIXEL_BITS))}")


def read_image(path: Path) -> np.ndarray:
    """(H, W) gray or (H, W, 3) BGR image of ``path`` (8 or 16 bit, any format OpenCV reads);
    InsituError naming the file if it is missing or not an image."""
    return images.read_image(path, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR)


def preview(img: np.ndarray, c: LineCentres) -> bytes:
    """PNG of ``img`` (8-bit BGR) with the centres drawn as red dots."""
    if img.dtype != np.uint8:
        img = cv2.convertScaleAbs(img, alpha=255.0 / max(float(img.max()), 1.0))
    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
    for u, v in np.round(c.uv).astype(int):
        cv2.circle(out, (int(u), int(v)), 1, (0, 0, 255), -1)
    return cv2.imencode(".png", out)[1].tobytes()


def _measure(frames, off, preview_dir, *args):
    """The CSV text of every frame's centres (``photo_centres(img, *args[:3], off,
    args[3])``), the previews {path: PNG}, the frames without centres and one line per frame
    whose line is uncertain (:class:`~insitu.vision.centres.UncertainLine`)."""
    method, direction, channel, pixel_bits = args
    rows, pictures, empty, doubt = io.StringIO(), {}, [], []
    rows.write(COLUMNS + "\n")
    for path, img in frames:
        try:
            c = photo_centres(img, method, direction, channel, off, pixel_bits)
        except UncertainLine as e:
            c = LineCentres(*(np.zeros(0),) * 5)
            doubt.append(f"{path}: {e}")
        if not len(c):
            empty.append(str(path))
        for u, v, peak, width, q in zip(c.u, c.v, c.peak, c.width, c.contrast):
            rows.write(f"{path},{u:.3f},{v:.3f},{peak:.1f},{width:.2f},{q:.1f}\n")
        if preview_dir is not None:
            pictures[preview_dir / f"{path.stem}.png"] = preview(img, c)
    return rows, pictures, empty, doubt


@one_line_errors
def centres(
    images: Annotated[list[Path], typer.Argument(help="Photographs of a laser line (any "
                                                      "format OpenCV reads, gray or colour).")],
    out: Annotated[Path, typer.Option("-o", "--output", help="Centres file (.csv): "
                                      f"{COLUMNS}, one row per centre.")],
    method: Annotated[str, typer.Option(help="Centre method: "
                                        f"{', '.join(CENTRE_METHODS)}.")] = "steger",
    direction: Annotated[str, typer.Option(help="auto (from the image's structure), rows (the "
                                           "line runs along the rows) or cols.")] = "auto",
    channel: Annotated[str, typer.Option(help="Colour images: auto (the laser's colour, found "
                                         "from the image), r, g or b.")] = "auto",
    background: Annotated[Path | None, typer.Option(
        help="A photograph of the same view with the laser off, taken away from each "
             "image.")] = None,
    pixel_bits: Annotated[int | None, typer.Option(
        help="Significant bits of the images' pixels: 10 or 12 for a Mono10/Mono12 camera "
             "whose 16-bit files hold 0 … 1023 / 4095 (default: the file's depth).")] = None,
    preview_dir: Annotated[Path | None, typer.Option(
        "--preview", help="Folder (created) for one PNG per image with the centres drawn.")] = None,
) -> None:
    """Find the laser line's sub-pixel centres in each image (one per column, or per row for a
    line running down the image) and write them all to one CSV: u, v (px, image x and y),
    peak (gray value), width (px) and quality (the line's contrast over its local
    background, gray values). A colour image's line is taken where the light has the laser's
    colour; a thin ridge across at least 20 columns (or rows) is a line, a glint, a lamp or
    the edge of a bright object is not. An image without a line gives no rows and is
    reported; so is one whose line carries no more laser colour than the colour fringes at
    its edges (it could be any edge: give --background), and one where lines run side by
    side that could each be the stripe (a reflection in a glossy floor)."""
    _check_options(method, direction, channel, pixel_bits)
    check_output(out, ".csv")
    if preview_dir is not None and preview_dir.exists() and not preview_dir.is_dir():
        raise InsituError(f"--preview {preview_dir}: not a folder")
    frames = [(p, read_image(p)) for p in images]          # every input checked before writing
    off = read_image(background) if background is not None else None
    if off is not None and (odd := next((p for p, i in frames if i.shape != off.shape), None)):
        raise InsituError(f"--background {background}: shape {off.shape}, but {odd} has "
                          f"{dict(frames)[odd].shape} (the same camera's view, laser off)")
    rows, pictures, empty, doubt = _measure(frames, off, preview_dir, method,
                                            None if direction == "auto" else direction,
                                            channel, pixel_bits)
    if len(empty) == len(frames):
        raise InsituError(f"no laser line found in {'any of the ' if len(frames) > 1 else ''}"
                          f"{len(frames)} image{'s' if len(frames) > 1 else ''}"
                          + (f"; {doubt[0]}" if len(doubt) == 1 == len(frames) else ""))
    if preview_dir is not None:
        preview_dir.mkdir(parents=True, exist_ok=True)
        for name, png in pictures.items():
            atomic_write_bytes(name, png)
    atomic_write_text(out, rows.getvalue())
    n = rows.getvalue().count("\n") - 1
    console.print(f"{n} centres from {len(frames) - len(empty)} of {len(frames)} images "
                  f"({method}) → {out}" + (f"; previews in {preview_dir}" if preview_dir else ""))
    if empty:
        console.print(f"no line found in: {', '.join(empty)}")
    for line in doubt:
        console.print(f"warning: not measured, {line}")
