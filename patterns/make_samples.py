"""Write the sample patterns beside this file (run: .venv/bin/python patterns/make_samples.py).

logo.svg is hand-written below; part.dxf is drawn with ezdxf; qr.png comes from segno (10 px
per module at 254 dpi, so 1 mm modules); fiducials.svg is a 5 × 5 grid of Ø1 mm circles at a
5 mm pitch, centred like insitu.patterns.fiducial_grid (exact SVG circles, readable anywhere).
"""

from __future__ import annotations

import io
from pathlib import Path

import ezdxf
import segno

from insitu.formats.atomic import atomic_write_bytes, atomic_write_text
from insitu.patterns import fiducial_centres

HERE = Path(__file__).resolve().parent

LOGO = """<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="40mm" height="20mm" viewBox="0 0 40 20">
  <title>insitu sample logo</title>
  <!-- a ring: two circles in one path, even-odd fill leaves the inner one empty -->
  <path fill="#1a1a1a" fill-rule="evenodd"
        d="M 10 2 A 8 8 0 1 1 10 18 A 8 8 0 1 1 10 2 Z
           M 10 6 A 4 4 0 1 0 10 14 A 4 4 0 1 0 10 6 Z"/>
  <!-- a square turned 45 degrees by a transform -->
  <g transform="translate(24 10)">
    <rect x="-3" y="-3" width="6" height="6" fill="black" transform="rotate(45)"/>
  </g>
  <!-- a triangle with a white dot painted over it (a knock-out) -->
  <polygon points="30,17 38,17 34,3" fill="black"/>
  <circle cx="34" cy="13" r="1.5" fill="white"/>
  <!-- a stroked wave under it all, inside the page: an area, a line under a beam wider than 0.3 mm -->
  <path d="M 2 19 C 12 17, 28 21, 38 19" fill="none" stroke="black" stroke-width="0.3"/>
</svg>
"""


def part_dxf() -> str:
    """A 60 × 40 mm plate: lines, a rounded corner (arc), a wavy top edge (spline) and a
    Ø10 mm hole (circle) at (20, 20); units mm ($INSUNITS = 4)."""
    doc = ezdxf.new("R2010", units=ezdxf.units.MM)
    msp = doc.modelspace()
    msp.add_line((0, 0), (50, 0))
    msp.add_arc((50, 10), 10, -90, 0)                     # (50, 0) → (60, 10)
    msp.add_line((60, 10), (60, 40))
    msp.add_spline([(60, 40), (45, 44), (30, 40), (15, 36), (0, 40)])
    msp.add_line((0, 40), (0, 0))
    msp.add_circle((20, 20), 5)
    msp.add_lwpolyline([(38, 15), (50, 15), (50, 25), (38, 25)], close=True)  # a window
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue()


def fiducials_svg(rows=5, cols=5, pitch=5.0, diameter=1.0) -> str:
    """Circles at :func:`fiducial_centres`, on a page with a half-pitch margin (y down)."""
    w, h = cols * pitch, rows * pitch
    circles = "\n".join(f'  <circle cx="{x + w / 2:g}" cy="{h / 2 - y:g}" r="{diameter / 2:g}"/>'
                        for x, y in fiducial_centres(rows, cols, pitch))
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<svg xmlns="http://www.w3.org/2000/svg" '
            f'width="{w:g}mm" height="{h:g}mm" viewBox="0 0 {w:g} {h:g}">\n'
            f"  <title>fiducial grid {rows} x {cols}, pitch {pitch:g} mm, "
            f"diameter {diameter:g} mm</title>\n{circles}\n</svg>\n")


def main() -> None:
    atomic_write_text(HERE / "logo.svg", LOGO)
    atomic_write_text(HERE / "part.dxf", part_dxf())
    png = io.BytesIO()
    segno.make_qr("https://example.com/insitu", error="m").save(png, kind="png", scale=10,
                                                                border=4, dpi=254)
    atomic_write_bytes(HERE / "qr.png", png.getvalue())
    atomic_write_text(HERE / "fiducials.svg", fiducials_svg())
    print("wrote", ", ".join(["logo.svg", "part.dxf", "qr.png", "fiducials.svg"]))


if __name__ == "__main__":
    main()
