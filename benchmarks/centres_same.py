"""The line centres of every method on fixed frames, saved or compared with a saved set: a
change of how the centres are computed (not of what they are) must leave them within
``--tol`` px.

Frames: the scan recordings of ``tests/data`` (13: the three full-size frames, the seven
binning-2 ones, three spread over binning 4) and four frames spread over each independent
scan recording (``shared/recordings``, when present). Each frame is measured by
:func:`~insitu.vision.extract.extract_centres` with each method's settings, in the scan's
band (the head's focus range: what a scan runs) and over the whole frame. Compared: the same
columns, and the largest |Δ| of u, v, peak, width, contrast (and saturated, ambiguous equal).

Run: .venv/bin/python benchmarks/centres_same.py --save FILE.npz   (before a change)
     .venv/bin/python benchmarks/centres_same.py --compare FILE.npz [--tol 1e-6]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from insitu.formats.sequence import Sequence
from insitu.reconstruct.plane import band_and_side, line_runs_along_rows
from insitu.services.common import camera_model
from insitu.vision.extract import CentreSettings, extract_centres

ROOT = Path(__file__).resolve().parents[1]
SCANS = [("tests/data/scan-step-block-full", None), ("tests/data/scan-step-block-b2", None),
         ("tests/data/scan-step-block-b4", 3)]
RECORDINGS = ROOT.parent / "shared" / "recordings"
FIELDS = ("u", "v", "peak", "width", "contrast", "saturated", "ambiguous")


def frames():
    """(name, image, camera, head, start, end) of every frame compared."""
    dirs = [(ROOT / d, n) for d, n in SCANS]
    dirs += [(p.parent, 4) for p in sorted(RECORDINGS.glob("*/sequence.json"))]
    for d, n in dirs:
        seq = Sequence.open(d)
        if seq.kind != "scan":
            continue
        idx = range(len(seq)) if n is None else np.linspace(0, len(seq) - 1, n).round()
        for i in dict.fromkeys(int(k) for k in idx):
            f = seq.spec.frames[i]
            yield (f"{d.name}/{i}", seq.read_frame(i), camera_model(seq.camera), seq.scan_head,
                   np.asarray(f.line.start, float), np.asarray(f.line.end, float))


def centres() -> dict[str, np.ndarray]:
    out = {}
    for name, img, cam, head, start, end in frames():
        rows = line_runs_along_rows(cam, start, end)
        lo, hi, upper = band_and_side(cam, start, end, head.pivot_height_mm,
                                      tuple(head.z_range_mm), along_rows=rows)
        for method in ("gray", "gaussian", "steger"):
            s = CentreSettings(method=method)
            for where, band in (("band", (lo, hi)), ("frame", None)):
                c = extract_centres(img, s, band, rows, upper if band else 0)
                for f in FIELDS:
                    out[f"{name}|{method}|{where}|{f}"] = np.asarray(getattr(c, f))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--save", type=Path)
    ap.add_argument("--compare", type=Path)
    ap.add_argument("--tol", type=float, default=1e-6)
    a = ap.parse_args()
    now = centres()
    if a.save:
        np.savez_compressed(a.save, **now)
        print(f"{len(now) // len(FIELDS)} sets of centres saved to {a.save}")
    if not a.compare:
        return
    before = dict(np.load(a.compare))
    worst, bad = {f: 0.0 for f in FIELDS}, []
    for key in sorted(set(before) | set(now)):
        x, y = before.get(key), now.get(key)
        if x is None or y is None or x.shape != y.shape:
            shapes = [None if z is None else z.shape for z in (x, y)]
            bad.append(f"{key}: {shapes[0]} → {shapes[1]}")
            continue
        field = key.rsplit("|", 1)[1]
        d = float(np.max(np.abs(x.astype(float) - y.astype(float)), initial=0.0))
        worst[field] = max(worst[field], d)
    points = sum(len(v) for k, v in now.items() if k.endswith("|u"))
    print(f"{len(now) // len(FIELDS)} sets, {points} centres; largest |Δ|: "
          + ", ".join(f"{f} {d:.3g}" for f, d in worst.items()))
    for b in bad[:20]:
        print("  differs:", b)
    ok = not bad and max(worst.values()) <= a.tol
    print("same within", a.tol, "px" if ok else "px: NO")
    raise SystemExit(0 if ok else 1)


if __name__ == "__main__":
    main()
