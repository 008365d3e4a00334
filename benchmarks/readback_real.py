"""Read-back on photographs our code did not draw: for each photo, plain zxing-cpp on the raw
image (one call, its defaults) beside our path (``insitu inspect PHOTO``:
:func:`insitu.vision.code_photo.read_photo`, the decoding ladder, the rectification by the
code's corners and the ISO/IEC TR 29158-style grade), a table with totals.

Default: the committed photos (tests/data/real-codes). The whole set: zxing-cpp's test images
(Apache-2.0), e.g.
    git clone --depth 1 https://github.com/zxing-cpp/zxing-cpp /tmp/zxing-cpp
    .venv/bin/python benchmarks/readback_real.py /tmp/zxing-cpp/test/samples/datamatrix-3 \\
        /tmp/zxing-cpp/test/samples/datamatrix-5 /tmp/zxing-cpp/test/samples/qrcode-2
A photo's expected text is its NAME.txt beside it (zxing-cpp's layout) or, for the committed
ones, the table in their README; compared without control characters (or the reader's
pictures of them), GS1's parentheses and white space.
"""

from __future__ import annotations

import re
import sys
import time
from pathlib import Path

import cv2
import zxingcpp
from rich.console import Console
from rich.table import Table

from insitu.vision.code_photo import read_photo
from insitu.vision.dpm_grade import letter

COMMITTED = Path(__file__).resolve().parents[1] / "tests" / "data" / "real-codes"
EXTS = (".png", ".jpg", ".jpeg", ".webp", ".bmp", ".tif", ".tiff")


def _norm(text: str) -> str:
    """The text without control characters, their printable pictures (the reader's HRI),
    GS1's parentheses or white space."""
    return re.sub(r"[\x00-\x20\x7f\u2400-\u243f()]", "", text)


def _expected(photo: Path) -> str | None:
    txt = photo.with_suffix(".txt")
    if txt.is_file():
        return txt.read_text(errors="replace")
    readme = photo.parent / "README.md"
    if readme.is_file():
        for line in readme.read_text().splitlines():
            cells = [c.strip() for c in line.split("|")]
            if len(cells) > 5 and cells[1] == photo.name:
                return cells[4]
    return None


def main() -> None:
    folders = [Path(a) for a in sys.argv[1:]] or [COMMITTED]
    photos = sorted(p for f in folders for p in f.iterdir() if p.suffix.lower() in EXTS)
    t = Table(title="codes in photographs: plain zxing-cpp vs our read-back path")
    for col in ("photo", "plain", "ours", "= text", "module px", "UEC", "grade", "parameters",
                "time"):
        t.add_column(col)
    n = plain_n = ours_n = right = 0
    grades: dict[str, int] = {}
    for photo in photos:
        img = cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE)
        if img is None:
            continue
        expect = _expected(photo)
        n += 1
        plain = [b for b in zxingcpp.read_barcodes(img)
                 if b.format.name in ("QRCode", "MicroQRCode", "DataMatrix")]
        t0 = time.perf_counter()
        codes = read_photo(img)
        dt = time.perf_counter() - t0
        plain_n += bool(plain)
        ours_n += bool(codes)
        ok = bool(codes) and expect is not None and any(_norm(c.text) == _norm(expect)
                                                        for c in codes)
        right += ok
        c = codes[0] if codes else None
        if c is not None:
            grades[letter(c.overall)] = grades.get(letter(c.overall), 0) + 1
        t.add_row(f"{photo.parent.name}/{photo.name}", "yes" if plain else "-",
                  "yes" if codes else "-", "?" if expect is None else ("yes" if ok else "NO"),
                  "" if c is None else f"{c.module_px:.1f}",
                  "" if c is None or c.uec is None else f"{c.uec:.2f}",
                  "" if c is None else letter(c.overall),
                  "" if c is None else c.grades.summary(), f"{dt:.2f} s")
    Console(width=200).print(t)
    dist = ", ".join(f"{k} {grades[k]}" for k in "ABCDF" if k in grades)
    print(f"{n} photos: plain zxing-cpp decodes {plain_n}, our path {ours_n} "
          f"({right} = the expected text); grades {dist}")


if __name__ == "__main__":
    main()
