"""A plain folder of board photos (no sequence.json): the ``--board`` text and the images.

``--board COLSxROWSxSQUARE_MM`` (e.g. ``9x6x25``: inner corners, square side in mm);
``--charuco DICT[:MARKER_MM]`` makes it a ChArUco board. Images: every .png, .jpg, .jpeg, .bmp,
.tif, .tiff in the folder, sorted by name, read unchanged (8 or 16 bit) and colour made grey.
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

from insitu.calibrate.camera import BoardSpec
from insitu.errors import CalibrationError
from insitu.formats.bounds import BOUNDS
from insitu.formats.images import read_image
from insitu.formats.limits import check_inside

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
_BOARD = re.compile(r"^\s*(\d+)\s*[xX×]\s*(\d+)\s*[xX×]\s*(\d+(?:\.\d*)?|\.\d+)\s*$")


def parse_board(text: str, charuco: str | None = None) -> BoardSpec:
    """``"9x6x25"`` → a 9 × 6 inner-corner board of 25 mm squares; ``charuco``
    ``"DICT_4X4_50[:MARKER_MM]"`` for a ChArUco board. CalibrationError naming the text."""
    m = _BOARD.match(text)
    if not m:
        raise CalibrationError(f"board {text!r}: expected COLSxROWSxSQUARE_MM, e.g. 9x6x25 "
                               "(inner corners across, inner corners down, square side in mm)",
                               field="board")
    cols, rows, square = int(m[1]), int(m[2]), float(m[3])
    for what, value, bound in (("columns", cols, "board_corners"), ("rows", rows, "board_corners"),
                               ("square side", square, "length_mm")):
        why = BOUNDS[bound].problem(value)
        if why is not None:
            raise CalibrationError(f"board {text!r}: {what} {why}", field="board")
    spec: dict = {"cols": cols, "rows": rows, "square_mm": square}
    if charuco is not None:
        name, _, marker = charuco.partition(":")
        spec["charuco"] = {"dictionary": name}
        if marker:
            try:
                spec["charuco"]["marker_mm"] = float(marker)
            except ValueError:
                raise CalibrationError(f"charuco {charuco!r}: expected DICT[:MARKER_MM], "
                                       "e.g. DICT_4X4_50:7", field="charuco") from None
            why = BOUNDS["length_mm"].problem(spec["charuco"]["marker_mm"])
            if why is not None:
                raise CalibrationError(f"charuco {charuco!r}: marker side {why}",
                                       field="charuco")
    return BoardSpec.from_spec(spec)


def image_files(folder: str | Path) -> list[Path]:
    """The folder's images, sorted by name. CalibrationError if there is none or one is a
    symlink that leads out of the folder."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CalibrationError(f"{folder}: " + ("not a folder" if folder.exists()
                                                else "no such folder"))
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise CalibrationError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) and no "
                               "sequence.json")
    for p in files:
        check_inside(p, folder, "photo", CalibrationError)
    return files


def read_grey(path: Path) -> np.ndarray:
    """One photo as a 2-D uint8/uint16 array; CalibrationError if it cannot be read."""
    img = read_image(path, error=CalibrationError)      # header checked before decoding
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    if img.dtype not in (np.uint8, np.uint16):
        raise CalibrationError(f"{path}: {img.dtype} pixels; expected 8 or 16 bit")
    return img
