"""The real-file corpus (tests/data/vector/, 50 SVG and DXF files of four projects): how many
load, how many are refused in one line, and how close each loaded SVG comes to cairosvg's
rendering of it (filled area and bounding box, the fair reference of
tests/unit/test_vector_corpus.py: tiles at ≥ 4 px per thinnest stroke, coverage-weighted
edges); DXFs with fills against ezdxf's drawing add-on.

    .venv/bin/python benchmarks/vector_corpus.py [--dxf]

Prints one row per file and the counts. To measure another tree's loader against the same
reference, put its ``src`` first on PYTHONPATH. Files our tests do not use, split in two
halves (tuned on one, the other scored once): benchmarks/vector_heldout.py."""

from __future__ import annotations

import argparse
import importlib.util
import time
from pathlib import Path

import numpy as np
import shapely

from insitu.errors import FormatError
from insitu.patterns import load_pattern

ROOT = Path(__file__).resolve().parents[1]


def _reference_module():
    """The corpus test module, for its references (one implementation of them)."""
    spec = importlib.util.spec_from_file_location(
        "vector_corpus_reference", ROOT / "tests" / "unit" / "test_vector_corpus.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dxf", action="store_true",
                    help="also compare DXFs with fills against ezdxf's drawing add-on (slow)")
    args = ap.parse_args()
    ref = _reference_module()
    loaded = refused = svg_ok = svg_n = dxf_ok = dxf_n = 0
    print(f"{'file':40s} {'result':8s} {'area ours':>12s} {'reference':>12s} {'diff':>8s}  box")
    for path in ref.FILES:
        t = time.perf_counter()
        try:
            p = load_pattern(path)
        except FormatError as e:
            refused += 1
            print(f"{path.name:40s} refused  {str(e)[len(str(path)) + 2:][:70]}")
            continue
        loaded += 1
        row = f"{path.name:40s} loaded  "
        if path.suffix.lower() == ".svg":
            svg_n += 1
            area, box, px, _ = ref._svg_reference(path)
            region = p.to_shapely()
            lines = shapely.union_all([region, *map(shapely.LineString, p.paths)])
            size = max(box[2] - box[0], box[3] - box[1])
            box_ok = bool(np.allclose(lines.bounds, box, atol=0.01 * size + px))
            d = region.area / area - 1
            svg_ok += abs(d) <= 0.01 and box_ok
            row += (f" {region.area:12.4f} {area:12.4f} {100 * d:+7.2f}%  "
                    f"{'ok' if box_ok else 'OFF'}")
        elif args.dxf and p.to_shapely().area > 0:
            dxf_n += 1
            area = ref._ezdxf_reference(path)
            d = p.to_shapely().area / area - 1 if area else float("inf")
            dxf_ok += abs(d) <= 0.01
            row += f" {p.to_shapely().area:12.4f} {area:12.4f} {100 * d:+7.2f}%"
        print(row + f"  ({time.perf_counter() - t:.1f} s)")
    print(f"\n{len(ref.FILES)} files: {loaded} loaded, {refused} refused in one line; "
          f"SVG within 1 % of cairosvg (area and box): {svg_ok} of {svg_n}"
          + (f"; DXF with fills within 1 % of ezdxf's drawing add-on: {dxf_ok} of {dxf_n}"
             if args.dxf else ""))


if __name__ == "__main__":
    main()
