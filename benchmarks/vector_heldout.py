"""The held-out vector corpus (issue 29; benchmarks/heldout_manifest.json, 76 files of six
public sources split in two by a hash of their names before any was loaded): each file loaded
as ``insitu pattern show`` loads it and compared with independent reference renderers —
for SVG cairosvg (the fair reference of tests/unit/test_vector_corpus.py) and resvg (the
renderer closest to the SVG specification; where the two disagree a file agreeing with
either counts), for DXF ezdxf's drawing add-on (fills rasterised by cairosvg, pattern
hatches as their lines, the extents of everything it draws). A file is *faithful* when its
filled area and its bounding box lie within 1 % of a reference's, *warned* when they do not
but the loader said why in a "warning:" line, *refused* when the loader refused it in one
line, and *silently wrong* otherwise.

    .venv/bin/python benchmarks/vector_heldout.py [--half tune|held-out|both] [NAME ...]

Tune on the "tune" half; the "held-out" half is scored once, at the end. Files whose licence
does not let us commit them are read from benchmarks/.heldout_cache/ (built by
benchmarks/heldout_build.py from snapshots of their repositories; a missing one is listed
with the repository, commit and path to take it from)."""

from __future__ import annotations

import argparse
import importlib.util
import json
import re
import time
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns import load_pattern

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "benchmarks" / "heldout_manifest.json"
PLACES = (ROOT / "tests" / "data" / "vector_heldout", ROOT / "benchmarks" / ".heldout_cache")


def _svg_reference_module():
    spec = importlib.util.spec_from_file_location(
        "vector_corpus_reference", ROOT / "tests" / "unit" / "test_vector_corpus.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _has_insunits(path: Path) -> bool:
    raw = path.read_bytes()
    start = raw.find(b"HEADER")
    return start >= 0 and b"$INSUNITS" in raw[start:raw.find(b"ENDSEC", start)]


def dxf_reference(path: Path, svg_ref) -> tuple[float, tuple | None]:
    """(filled area mm², extents (x0, y0, x1, y1) mm or None) as ezdxf's drawing add-on
    draws the model space: hatch patterns as lines, fills rasterised by cairosvg."""
    import ezdxf
    from ezdxf import recover, units
    from ezdxf.addons.drawing import Frontend, RenderContext, config, layout, svg
    from ezdxf.addons.drawing.recorder import Recorder

    try:
        doc = ezdxf.readfile(str(path))
    except Exception:  # noqa: BLE001 — as a CAD program would: the tolerant reader
        doc, _ = recover.readfile(str(path))
    code = int(doc.header.get("$INSUNITS", 0) or 0) if _has_insunits(path) else 0
    k = units.conversion_factor(code or 4, units.MM)
    cfg = config.Configuration(hatch_policy=config.HatchPolicy.NORMAL,
                               color_policy=config.ColorPolicy.BLACK,
                               background_policy=config.BackgroundPolicy.WHITE)
    rec = Recorder()
    Frontend(RenderContext(doc), rec, config=cfg).draw_layout(doc.modelspace())
    player = rec.player()
    bb = player.bbox()
    box = None if not bb.has_data else (bb.extmin.x * k, bb.extmin.y * k, bb.extmax.x * k,
                                        bb.extmax.y * k)
    be = svg.SVGBackend()
    player.replay(be)
    text = be.get_string(layout.Page(0, 0, layout.Units.mm),
                         settings=layout.Settings(scale=1, fit_page=False))
    text = re.sub(r"stroke: #[0-9a-fA-F]{6}", "stroke: none", text)   # fills only
    w, h = (float(re.search(rf'{a}="([0-9.]+)mm"', text)[1]) for a in ("width", "height"))
    if not (w > 0 and h > 0) or "fill: #" not in text.replace("fill: #ffffff", ""):
        return 0.0, box
    area, _, _ = svg_ref._dark_area(text.encode(), w, h, 6000)
    return area * k * k, box


def resvg_reference(path: Path, svg_ref):
    """(dark area mm², bbox mm y up, pixel mm) of resvg's rendering of the page as
    svgelements sizes it, at the resolution of the cairosvg reference (one tile)."""
    import resvg_py
    import svgelements as se

    from insitu.patterns.svg import _SVG_PPI
    from insitu.patterns.vector import BEAM_MM, MM_PER_PX

    doc = se.SVG.parse(str(path), ppi=_SVG_PPI)
    W, H = float(doc.width), float(doc.height)
    widths = [float(el.stroke_width) for el in doc.elements()
              if isinstance(el, se.Shape) and el.stroke is not None
              and el.stroke.value is not None and el.stroke_width]
    thinnest = min([w for w in widths if w * MM_PER_PX >= BEAM_MM] or [W])
    k = min(max(4.0 / thinnest, 3000.0 / max(W, H)), (16e6 / (W * H)) ** 0.5)
    png = resvg_py.svg_to_bytes(svg_path=str(path), width=round(W * k), height=round(H * k),
                                font_family="DejaVu Sans", sans_serif_family="DejaVu Sans",
                                serif_family="DejaVu Serif", monospace_family="DejaVu Sans Mono",
                                font_dirs=["/usr/share/fonts"])
    cov = svg_ref._coverage(bytes(png), svg_ref._dark_paints(doc, se))
    px = MM_PER_PX * W / cov.shape[1]
    ys, xs = np.nonzero(cov >= 0.5)
    h = cov.shape[0] * px
    box = None if not len(xs) else (xs.min() * px, h - (ys.max() + 1) * px,
                                    (xs.max() + 1) * px, h - ys.min() * px)
    return float(cov.sum()) * px * px, box, px


def _compare(p, ref_area: float, ref_box, px: float) -> tuple[float, float]:
    """(relative area difference, box deviation as a fraction of the reference's size)."""
    region = p.to_shapely()
    drawn = shapely.union_all([region, *map(shapely.LineString,
                                            [q for q in p.paths if len(q) >= 2])])
    area = region.area
    d_area = 0.0 if ref_area == area == 0 else (area / ref_area - 1 if ref_area else np.inf)
    if ref_box is None or drawn.is_empty:
        return d_area, 0.0 if ref_box is None and drawn.is_empty else np.inf
    size = max(ref_box[2] - ref_box[0], ref_box[3] - ref_box[1], 1e-9)
    dev = max(abs(a - b) for a, b in zip(drawn.bounds, ref_box))
    return d_area, max(0.0, dev - px) / size


def score(row: dict, path: Path, svg_ref) -> dict:
    t = time.perf_counter()
    try:
        p = load_pattern(path)
    except FormatError as e:
        return {"result": "refused", "time": time.perf_counter() - t,
                "note": str(e)[len(str(path)) + 2:]}
    took = time.perf_counter() - t
    refs = []
    if path.suffix.lower() in (".svg", ".svgz"):
        for name, fn in (("cairosvg", lambda: svg_ref._svg_reference(path)[:3]),
                         ("resvg", lambda: resvg_reference(path, svg_ref))):
            try:
                refs.append((name, *fn()))
            except Exception as e:  # noqa: BLE001 — a reference that cannot draw the file
                print(f"  ({name} cannot draw {path.name}: {' '.join(str(e).split())[:80]})")
    else:
        refs.append(("ezdxf", *dxf_reference(path, svg_ref), 0.0))
    scored = [(name, area, *_compare(p, area, box, px)) for name, area, box, px in refs]
    name, ref_area, d_area, d_box = min(scored, key=lambda s: max(abs(s[2]), s[3]))
    ok = abs(d_area) <= 0.01 and d_box <= 0.01
    warnings = [n.removeprefix("warning: ") for n in p.notes if n.startswith("warning:")]
    result = "faithful" if ok else "warned" if warnings else "SILENTLY WRONG"
    others = "".join(f" [{n} {100 * a:+.1f}% {100 * b:.1f}%]" for n, _, a, b in scored
                     if n != name)
    return {"result": result, "time": took, "area": p.to_shapely().area, "ref": ref_area,
            "d_area": d_area, "d_box": d_box, "ref_name": name,
            "note": "; ".join(warnings) + others}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=("tune", "held-out", "both"), default="tune")
    ap.add_argument("names", nargs="*", help="only these files")
    args = ap.parse_args()
    rows = [r for r in json.loads(MANIFEST.read_text())
            if (args.half == "both" or r["half"] == args.half)
            and (not args.names or r["file"] in args.names)]
    svg_ref = _svg_reference_module()
    out = []
    print(f"{'half':8s} {'source':16s} {'file':34s} {'result':15s} {'area mm²':>10s} "
          f"{'ref mm²':>10s} {'area':>8s} {'box':>7s} {'ref':8s} {'s':>6s}  note")
    for r in rows:
        path = next((d / r["source"] / r["file"] for d in PLACES
                     if (d / r["source"] / r["file"]).is_file()), None)
        if path is None:
            print(f"{r['half']:8s} {r['source']:16s} {r['file'][:34]:34s} missing: take "
                  f"{r['path']} at {r['commit'][:10]} of GitHub {r['repo']} "
                  "(benchmarks/heldout_build.py)")
            continue
        s = {**r, **score(r, path, svg_ref)}
        out.append(s)
        nums = (f"{s['area']:10.4g} {s['ref']:10.4g} {100 * s['d_area']:+7.2f}% "
                f"{100 * s['d_box']:6.2f}% {s['ref_name']:8s}" if "area" in s else f"{'':48s}")
        print(f"{s['half']:8s} {s['source']:16s} {s['file'][:34]:34s} {s['result']:15s} "
              f"{nums} {s['time']:6.2f}  {s['note'][:110]}", flush=True)
    for half in ("tune", "held-out"):
        got = [s for s in out if s["half"] == half]
        if not got:
            continue
        counts = {k: sum(s["result"] == k for s in got)
                  for k in ("faithful", "warned", "refused", "SILENTLY WRONG")}
        worst = sorted((s for s in got if "area" in s),
                       key=lambda s: -max(abs(s["d_area"]), s["d_box"]))[:3]
        slow = max(got, key=lambda s: s["time"])
        print(f"\n{half}: {len(got)} files — " + ", ".join(f"{v} {k}" for k, v in counts.items())
              + f"; slowest {slow['file']} {slow['time']:.1f} s; worst: " + ", ".join(
                  f"{s['file']} area {100 * s['d_area']:+.1f}% box {100 * s['d_box']:.1f}% "
                  f"({s['result']})" for s in worst))


if __name__ == "__main__":
    main()
