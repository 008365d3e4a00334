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
from insitu.vision.centres import CENTRE_METHODS, LineCentres, line_centres

COLUMNS = "file,u,v,peak,width,quality"


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
    channel: Annotated[str, typer.Option(help="Colour images: auto (the channel where the "
                                         "line stands out most), r, g or b.")] = "auto",
    preview_dir: Annotated[Path | None, typer.Option(
        "--preview", help="Folder (created) for one PNG per image with the centres drawn.")] = None,
) -> None:
    """Find the laser line's sub-pixel centres in each image (one per column, or per row for a
    line running down the image) and write them all to one CSV: u, v (px, image x and y),
    peak (gray value), width (px) and quality (the line's contrast over its local
    background, gray values). An image without a line gives no rows and is reported."""
    if method not in CENTRE_METHODS:
        raise InsituError(f"--method {method!r}: expected {one_of(CENTRE_METHODS)}")
    if direction not in ("auto", "rows", "cols"):
        raise InsituError(f"--direction {direction!r}: expected 'auto', 'rows' or 'cols'")
    if channel not in ("auto", "r", "g", "b"):
        raise InsituError(f"--channel {channel!r}: expected 'auto', 'r', 'g' or 'b'")
    check_output(out, ".csv")
    if preview_dir is not None and preview_dir.exists() and not preview_dir.is_dir():
        raise InsituError(f"--preview {preview_dir}: not a folder")
    frames = [(p, read_image(p)) for p in images]          # every input checked before writing
    rows, pictures, empty = io.StringIO(), {}, []
    rows.write(COLUMNS + "\n")
    kw = dict(CENTRE_METHODS[method].defaults)
    for path, img in frames:
        c = line_centres(img, method, None if direction == "auto" else direction,
                         channel=channel, **kw)
        if not len(c):
            empty.append(str(path))
        for u, v, peak, width, q in zip(c.u, c.v, c.peak, c.width, c.contrast):
            rows.write(f"{path},{u:.3f},{v:.3f},{peak:.1f},{width:.2f},{q:.1f}\n")
        if preview_dir is not None:
            pictures[preview_dir / f"{path.stem}.png"] = preview(img, c)
    if len(empty) == len(frames):
        raise InsituError(f"no laser line found in {'any of the ' if len(frames) > 1 else ''}"
                          f"{len(frames)} image{'s' if len(frames) > 1 else ''}")
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
