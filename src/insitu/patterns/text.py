"""Text → :class:`Pattern`: glyph outlines from any installed font (fontTools), in mm, y up.

Fonts are found by family name through fontconfig (``fc-match``; "DejaVu Serif",
"DejaVu Serif Bold" or "DejaVu Serif:style=Bold") or given as a .ttf/.otf path. A family
that is not installed is an error, never a silent fallback to another font.
"""

from __future__ import annotations

import functools
import shutil
import subprocess
from pathlib import Path

import numpy as np

from insitu.errors import FormatError
from insitu.patterns.model import Pattern, normalised
from insitu.patterns.vector import bezier_points

DEFAULT_FONT = "DejaVu Sans"
_FONT_DIRS = ("/usr/share/fonts", "/usr/local/share/fonts", "~/.local/share/fonts", "~/.fonts")


def _fc_match(pattern: str) -> tuple[list[str], str, str] | None:
    """(families, style, file) fontconfig picks for ``pattern``, or None without fontconfig."""
    exe = shutil.which("fc-match")
    if exe is None:
        return None
    try:
        out = subprocess.run([exe, "-f", "%{family}|%{style}|%{file}", pattern],
                             capture_output=True, text=True, timeout=10, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    fam, _, rest = out.partition("|")
    style, _, file = rest.partition("|")
    return [f.strip().lower() for f in fam.split(",")], style.lower(), file.strip()


@functools.lru_cache(maxsize=32)
def find_font(name: str) -> Path:
    """Path of the font file for a family name (with optional style) or a font file path."""
    p = Path(name).expanduser()
    if p.suffix.lower() in (".ttf", ".otf", ".ttc") or "/" in name:
        if not p.is_file():
            raise FormatError(f"font file {p} does not exist")
        return p
    family, _, style = name.partition(":style=")
    words = family.split()
    # "DejaVu Serif Bold Italic" → family "DejaVu Serif", style "Bold Italic", and so on
    tries = [(family, style)] + ([] if style else
                                 [(" ".join(words[:i]), " ".join(words[i:]))
                                  for i in range(len(words) - 1, 0, -1)])
    for fam, sty in tries:
        got = _fc_match(f"{fam}:style={sty}" if sty else fam)
        if got is None:
            break
        fams, got_style, file = got
        styles = [x.strip() for x in got_style.split(",")]
        if fam.strip().lower() in fams and (not sty or sty.lower() in styles) and file:
            return Path(file)
    else:
        raise FormatError(f"font {name!r} is not installed (fc-list lists the installed ones)")
    # no fontconfig: look for a file named like the family ("DejaVu Sans" → DejaVuSans.ttf)
    stem = name.replace(" ", "").replace(":style=", "-").lower()
    for d in _FONT_DIRS:
        for f in Path(d).expanduser().rglob("*"):
            if f.suffix.lower() in (".ttf", ".otf") and f.stem.lower() == stem:
                return f
    raise FormatError(f"font {name!r} not found (no fontconfig; give a .ttf/.otf path)")


class _FlattenPen:
    """A fontTools pen recording glyph contours as polylines (font units)."""

    def __init__(self, glyphset, tol: float):
        from fontTools.pens.basePen import BasePen

        outer = self

        class Pen(BasePen):
            def _moveTo(self, pt):
                outer.cur = [pt]

            def _lineTo(self, pt):
                outer.cur.append(pt)

            def _qCurveToOne(self, p1, p2):
                outer.cur.extend(map(tuple, bezier_points([outer.cur[-1], p1, p2], tol)[1:]))

            def _curveToOne(self, p1, p2, p3):
                outer.cur.extend(map(tuple, bezier_points([outer.cur[-1], p1, p2, p3],
                                                          tol)[1:]))

            def _closePath(self):
                if len(outer.cur) >= 3:
                    outer.rings.append(np.array(outer.cur, np.float64))
                outer.cur = []

            _endPath = _closePath

        self.cur: list = []
        self.rings: list[np.ndarray] = []
        self.pen = Pen(glyphset)


@functools.lru_cache(maxsize=8)
def _font(path: Path):
    from fontTools.ttLib import TTFont

    try:
        return TTFont(str(path), fontNumber=0, lazy=True)
    except Exception as e:  # noqa: BLE001 — a broken font file, said in one line
        raise FormatError(f"font file {path}: not a readable TrueType/OpenType font ({e})") from e


def text_pattern(text: str, font: str = DEFAULT_FONT, size_mm: float = 10.0,
                 line_spacing: float = 1.0, tol_mm: float = 0.002) -> Pattern:
    """Outlines of ``text`` as filled contours (mm, y up). ``size_mm`` is the font size (the
    em square; capitals are about 0.7 of it); the first line's baseline is y = 0, starting at
    x = 0; lines ("\\n") go down by the font's line height × ``line_spacing``. No kerning."""
    if not text.strip():
        raise FormatError(f"text:{text!r}: no text to mark (empty pattern)")
    if not size_mm > 0:
        raise FormatError(f"text:{text!r}: font size must be > 0 mm, got {size_mm}")
    f = _font(find_font(font))
    try:
        upem = float(f["head"].unitsPerEm)
        cmap = f.getBestCmap() or {}
        gs = f.getGlyphSet()
        hmtx = f["hmtx"]
        hhea = f["hhea"]
        line_h = (hhea.ascent - hhea.descent + hhea.lineGap) * line_spacing
        k = size_mm / upem
        missing = sorted({c for c in text if ord(c) not in cmap and not c.isspace()})
        if missing:
            raise FormatError(f"font {font!r} ({find_font(font).name}) has no glyph for "
                              f"{''.join(missing)!r}")
        contours: list[np.ndarray] = []
        for row, line in enumerate(text.split("\n")):
            x = 0.0
            for ch in line:
                gname = cmap.get(ord(ch)) or cmap.get(32, ".notdef")
                pen = _FlattenPen(gs, tol_mm / k)
                gs[gname].draw(pen.pen)
                off = np.array([x, -row * line_h])
                contours += [(r + off) * k for r in normalised(pen.rings, "nonzero")]
                x += hmtx[gname][0]
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 — a font that cannot be drawn
        raise FormatError(f"font {font!r}: cannot draw its glyphs ({e})") from e
    p = Pattern(tuple(contours), (), f"text:{text}")
    if p.is_empty:
        raise FormatError(f"text:{text!r}: no visible glyphs (empty pattern)")
    return p
