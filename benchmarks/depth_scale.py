"""The height scale a depth carries: how far a measured height difference departs from the
true one, as a relative error, with Method 1 (the head's geometry alone) and Method 2 (a
height calibration), on the independent recordings and on our simulator.

- Step block, each step along y between flat levels (the table and the four tops): the
  points of an 8 mm band on each side (≥ 1 mm from the walls, over the top's x span) fit
  height error = a + b x + c y + Δ·(upper side) robustly, the error's tilt over the field
  common to both sides: Δ is the step's error at the same x, y, as a pocket's depth is.
- Arc: over its top (≥ 1 mm from walls) the height error fits a + b x + c y + s·z_true −
  shift·∇z_true: s, crown against edges. It is not a flat pocket's scale: the edges slope
  40–46° (a slope's own bias enters), and a lateral stretch of the cloud across the axis,
  or a lateral shift that grows over the field, reads as scale on a cylinder (Method 1's
  height offset tilting over the field moves its points along the camera's rays by
  ≈ 0.45 × as much: ≈ 2 × 0.45 × the tilt of scale).
- Method 1's scale from our simulator's truth (no image, ``--geometry``): a 0.5 mm pocket's
  depth along the true beam, seen by the true camera, intersected with the light plane the
  operator's camera and the head's nominal pivot give; with and without the flawless field
  correction (the plate benchmark and a scan without a field correction file: without).

The ± is a jackknife over the scan's lines (a line's speckle and its light sheet are its
own). Independent recordings: ``shared/recordings`` (truth.json read here only, to score),
Method 2 from ``height-calibration-coarse-independent``. Our simulator: the coarse
calibration's 3 × 3 (plate at −15, 0, 15 mm, lines at −30, 0, 30 mm) or with ``--fine`` the
7 × 13 of ``insitu calibrate height``; the parts scanned with lines ``--spacing`` mm apart.
Last: per data and method, the steps' inverse-variance mean.

Run: .venv/bin/python benchmarks/depth_scale.py [--sim-seeds 0,1,2,3] [--spacing 1.0]
     [--fine] [--geometry 0,1,2,3,5,7,45,47,49,51] [--recordings DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.geometry.beams import light_plane
from insitu.reconstruct.plan import scan_lines
from insitu.reconstruct.plane import intersect_plane
from insitu.reconstruct.scan import ScanReconstructor
from insitu.services import calibrate_height, centre_settings, height_model, scan_replay
from insitu.services.record import record_height_calibration
from insitu.services.station import simulated
from insitu.sim.devices import SimCamera, SimScanHead
from insitu.sim.rig import default_rig
from insitu.sim.workpieces import make_workpiece
from insitu.sim.world import SimWorld

console = Console(width=150)
DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "recordings"
MARGIN_MM = 1.0
COARSE = {"heights": (-15.0, 0.0, 15.0), "offsets": (-30.0, 0.0, 30.0)}
ARC_SAGITTA_MM = 8.5
"""The independent arc's crown over its edges (11.5 and 3 mm); our simulator's arc the same."""


def on_table(part):
    """The part's height function with the table (z = 0) where the part is not: (x, y) → z."""
    def height(x, y):
        z = part.height(x, y)
        return np.where(np.isfinite(z), z, 0.0)
    return height


def flat(height, p: np.ndarray, margin: float = MARGIN_MM):
    """(N,) bool: points (N, ≥ 2) whose true height is the same ``margin`` mm all around,
    and their true heights (N,)."""
    z = height(p[:, 0], p[:, 1])
    ok = np.ones(len(p), bool)
    for dx, dy in ((margin, 0), (-margin, 0), (0, margin), (0, -margin)):
        ok &= np.abs(height(p[:, 0] + dx, p[:, 1] + dy) - z) < 1e-3
    return ok, z


def robust_fit(A: np.ndarray, b: np.ndarray, iterations: int = 8) -> np.ndarray:
    """Least squares A c ≈ b with Huber weights (k = 1.5 robust σ): c (M,)."""
    w = np.ones(len(b))
    for _ in range(iterations):
        c = np.linalg.lstsq(A * w[:, None], b * w, rcond=None)[0]
        r = b - A @ c
        s = max(1.4826 * np.median(np.abs(r)), 1e-6)
        w = np.sqrt(np.minimum(1.0, 1.5 * s / np.maximum(np.abs(r), 1e-12)))
    return c


def jackknife(estimate, p: np.ndarray, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``estimate(points, line) → (K,)`` on all lines, and its jackknife σ (K,) over lines."""
    full = np.asarray(estimate(p, line))
    ids = np.unique(line)
    loo = np.array([estimate(p[line != k], line[line != k]) for k in ids])
    n = len(ids)
    return full, np.sqrt((n - 1) / n * np.sum((loo - loo.mean(0)) ** 2, axis=0))


def step_rows(height, p: np.ndarray, line: np.ndarray, band_mm: float = 8.0):
    """(label, true difference mm, relative error, its σ) of each step along y between flat
    levels: the points of a band ``band_mm`` wide on each side of the step (beyond the 1 mm
    margin, over the higher level's x span) fit height error = a + b x + c y + Δ·(upper
    side), robustly: the error's tilt over the field common to both, Δ the step's error at
    the same x, y."""
    x_top = p[np.abs(height(p[:, 0], p[:, 1])) > 0, 0]
    xc, half = 0.5 * (x_top.min() + x_top.max()), 0.5 * np.ptp(x_top) - MARGIN_MM
    ys = np.arange(p[:, 1].min(), p[:, 1].max(), 0.01)
    zs = height(np.full_like(ys, xc), ys)
    jumps = np.flatnonzero(np.abs(np.diff(zs)) > 0.1)
    steps = [(0.5 * (ys[j] + ys[j + 1]), zs[j], zs[j + 1]) for j in jumps]

    def errors(q: np.ndarray, _line) -> np.ndarray:
        ok, z = flat(height, q)
        ok &= np.abs(q[:, 0] - xc) <= half
        out = []
        for y0, _, _ in steps:
            dy = q[:, 1] - y0
            b = ok & (np.abs(dy) >= MARGIN_MM) & (np.abs(dy) <= MARGIN_MM + band_mm)
            A = np.column_stack([np.ones(b.sum()), q[b, 0] - xc, dy[b], dy[b] > 0])
            out.append(robust_fit(A, q[b, 2] - z[b])[3])
        return np.array(out)
    err, sig = jackknife(errors, p, line)
    rows = []
    for (y0, za, zb), e, s in zip(steps, err, sig):
        lo, hi, sign = (za, zb, 1) if zb > za else (zb, za, -1)
        rows.append((f"{lo:g} → {hi:g} mm (y {round(y0) + 0:+d})", hi - lo, sign * e / (hi - lo),
                     s / (hi - lo)))
    return rows


def arc_scale(part, p: np.ndarray, line: np.ndarray, h: float = 0.05):
    """The arc's scale error over its top, ≥ 1 mm from walls: the robust fit of the height
    error to a + b·x + c·y + s·z_true − shift·∇z_true (the error's tilt over the field and the
    cloud's lateral shift taken out); (s, σ(s) by jackknife, true height span). A lateral
    stretch of the cloud across the arc's axis reads as scale here too (−2 × the stretch):
    on a cylinder the two cannot be told apart."""
    z = part.height(p[:, 0], p[:, 1])
    ok = np.isfinite(z)
    for dx, dy in ((MARGIN_MM, 0), (-MARGIN_MM, 0), (0, MARGIN_MM), (0, -MARGIN_MM)):
        ok &= np.isfinite(part.height(p[:, 0] + dx, p[:, 1] + dy))
    p, line = p[ok], line[ok]

    def slope(q, _line):
        zt = part.height(q[:, 0], q[:, 1])
        gx = (part.height(q[:, 0] + h, q[:, 1]) - part.height(q[:, 0] - h, q[:, 1])) / (2 * h)
        gy = (part.height(q[:, 0], q[:, 1] + h) - part.height(q[:, 0], q[:, 1] - h)) / (2 * h)
        A = np.column_stack([np.ones(len(q)), q[:, 0], q[:, 1], zt, gx, gy])
        return robust_fit(A, q[:, 2] - zt)[3:4]
    s, sig = jackknife(slope, p, line)
    zt = part.height(p[:, 0], p[:, 1])
    return float(s[0]), float(sig[0]), float(np.ptp(zt))


def independent_parts(root: Path) -> dict[str, tuple[str, object]]:
    """Scan folder → (kind "steps" / "arc", the true part), from each recording's truth.json."""
    out = {}
    for seq in sorted(root.glob("*/truth.json")):
        w = json.loads(seq.read_text()).get("workpiece") or {}
        p = w.get("params", {})
        if w.get("name") == "step-block":
            out[seq.parent.name] = ("steps", make_workpiece(
                "step-block", length=p["y_size"], width=p["x_size"], heights=p["heights"],
                x=p["center"][0], y=p["center"][1]))
        elif w.get("name") == "arc":
            x, y, angle = w["pose"]
            out[seq.parent.name] = ("arc", make_workpiece(
                "arc", width=p["x_size"], length=p["y_size"], height=p["top"],
                sagitta=p["top"] - p["edge"], x=x, y=y, angle_deg=angle))
    return out


def rows_of(kind: str, part, cloud) -> list[tuple[str, float, float, float]]:
    p, line = cloud.points, np.asarray(cloud.attributes["line"])
    if kind == "steps":
        return step_rows(on_table(part), p, line)
    s, sig, span = arc_scale(part, p, line)
    return [(f"crown − edges ({span:.1f} mm)", span, s, sig)]


def independent(root: Path, rows: list) -> None:
    """Each scan recording's rows (data, method, label, span mm, error, σ), appended."""
    cal = calibrate_height(root / "height-calibration-coarse-independent")
    for name, (kind, part) in independent_parts(root).items():
        for method, c in (("1 (geometry)", None), ("2 (coarse calibration)", cal)):
            rows += [(f"{name} (independent)", method, *r)
                     for r in rows_of(kind, part, scan_replay(root / name, c).cloud)]


def sim_scan(world: SimWorld, recs: dict, spacing: float) -> dict:
    """Scan the world's part with lines ``spacing`` mm apart; each reconstructor's cloud."""
    lo, hi = world.parts[0].bounds()
    cam, head = SimCamera(world), SimScanHead(world)
    for i, (a, b) in enumerate(scan_lines((lo[0] - 3, hi[0] + 3, lo[1] - 6, hi[1] + 6),
                                          spacing)):
        head.show_line(a, b)
        frame = cam.grab()
        for rec in recs.values():
            rec.add(i, frame, a, b)
    head.off()
    return {m: r.cloud() for m, r in recs.items()}


def simulator(seed: int, spacing: float, fine: bool, rows: list) -> None:
    """Our simulator's step block and arc on rig ``seed``: rows as :func:`independent`."""
    rig = default_rig(seed=seed)
    H = rig.operator.head.pivot_height_mm
    with tempfile.TemporaryDirectory() as tmp:
        kw = {} if fine else COARSE
        record_height_calibration(simulated(SimWorld(rig, seed=seed)), Path(tmp) / "h",
                                  cross=False, **kw)
        cal = calibrate_height(Path(tmp) / "h")
    cam, model = height_model(cal)
    parts = {"steps": make_workpiece("step-block"),
             "arc": make_workpiece("arc", sagitta=ARC_SAGITTA_MM)}
    cal_name = "fine calibration" if fine else "coarse calibration"
    for kind, part in parts.items():
        recs = {"1 (geometry)": ScanReconstructor(rig.operator.camera, H,
                                                  settings=centre_settings(cal)),
                f"2 ({cal_name})": ScanReconstructor(cam, H, height_model=model,
                                                     settings=centre_settings(cal))}
        clouds = sim_scan(SimWorld(rig, parts=[part], seed=seed + 1), recs, spacing)
        for method, cloud in clouds.items():
            rows += [(f"{part.name} (simulator, seed {seed})", method, *r)
                     for r in rows_of(kind, part, cloud)]


def method1_scale(rig, x: np.ndarray, y: np.ndarray, depth_mm: float = 0.5,
                  corrected: bool = False) -> np.ndarray:
    """(N,) Method 1's scale error for a pocket ``depth_mm`` deep at (x, y) (N,) mm on z = 0,
    from the truth alone (no image): the true beam of the line along y through each point
    (with ``corrected``, commanded through the flawless field correction, so it lands where
    asked) lit at 0 and −depth, seen by the true camera, intersected with the light plane
    the operator's camera and the head's nominal pivot give."""
    H = rig.operator.head.pivot_height_mm
    target = np.column_stack([x, y])
    o, d = rig.beams.rays(rig.ideal_correction()(target) if corrected else target)
    z = []
    for h in (0.0, -depth_mm):
        uv = rig.camera.project(o + ((h - o[:, 2]) / d[:, 2])[:, None] * d)
        z.append(np.array([intersect_plane(rig.operator.camera, uv[i:i + 1],
                                           light_plane(H, [xi, -1.0], [xi, 1.0]))[0, 2]
                           for i, xi in enumerate(x)]))
    return (z[0] - z[1]) / depth_mm - 1


def geometry(seeds: list[int], table: Table) -> None:
    """Method 1's scale for a 0.5 mm pocket from our simulator's truth: at the plate
    benchmark's pockets (x −7.5 … 7.5, y 0), and rms / largest over the field within ±30 and
    ±90 mm, the head uncorrected (as the plate benchmark and a scan without a field
    correction) and through the flawless field correction."""
    g = np.linspace(-90.0, 90.0, 13)
    gx, gy = (v.ravel() for v in np.meshgrid(g, g))
    plate = np.array([-7.5, -2.5, 2.5, 7.5])
    for seed in seeds:
        rig = default_rig(seed=seed)
        for corrected in (False, True):
            at = 100 * method1_scale(rig, plate, np.zeros(4), corrected=corrected)
            field = 100 * method1_scale(rig, gx, gy, corrected=corrected)
            inner = (np.abs(gx) <= 30) & (np.abs(gy) <= 30)
            table.add_row(str(seed), "flawless" if corrected else "none",
                          " ".join(f"{v:+.3f}" for v in at),
                          f"{np.sqrt(np.mean(field[inner] ** 2)):.3f} / "
                          f"{np.abs(field[inner]).max():.3f}",
                          f"{np.sqrt(np.mean(field ** 2)):.3f} / {np.abs(field).max():.3f}")


def report(rows: list) -> None:
    """The table of rows, then each data source's and method's steps, inverse-variance mean."""
    t = Table(title="height scale: (measured − true) / true height difference, % ± jackknife "
              "σ over the lines; what it makes of a 0.5 mm pocket's depth, µm")
    for col in ("data", "method", "difference", "scale error, %", "over it, µm",
                "on 0.5 mm, µm"):
        t.add_column(col)
    for data, method, label, span, e, s in rows:
        t.add_row(data, method, label, f"{100 * e:+.3f} ± {100 * s:.3f}",
                  f"{1000 * e * span:+.1f}", f"{500 * e:+.2f} ± {500 * s:.2f}")
    console.print(t)
    groups: dict = {}
    for data, method, label, _, e, s in rows:
        if "crown" not in label:
            source = "independent" if "independent" in data else "simulator"
            groups.setdefault((source, method), []).append((e, s))
    for (data, method), v in groups.items():
        e, s = np.array(v).T
        w = 1 / s ** 2
        console.print(f"{data}, method {method}: {len(v)} steps, mean "
                      f"{100 * np.dot(w, e) / w.sum():+.3f} ± {100 / np.sqrt(w.sum()):.3f} %, "
                      f"largest |error| {100 * np.abs(e).max():.3f} %", highlight=False)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--recordings", type=Path, default=DEFAULT)
    ap.add_argument("--sim-seeds", default="0,1,2,3", help="comma-separated; '' for none")
    ap.add_argument("--spacing", type=float, default=1.0, help="simulated scans' line step, mm")
    ap.add_argument("--fine", action="store_true", help="simulator: the 7 × 13 calibration")
    ap.add_argument("--geometry", default="0,1,2,3,5,7,45,47,49,51",
                    help="seeds of Method 1's scale from the truth; '' for none")
    args = ap.parse_args()
    geo = [int(s) for s in args.geometry.split(",") if s.strip()]
    if geo:
        t = Table(title="Method 1's scale error for a 0.5 mm pocket from our simulator's truth "
                  "(no image), %")
        for col in ("seed", "field correction", "plate's pockets (x −7.5 … 7.5)",
                    "within ±30 mm: rms / max", "within ±90 mm: rms / max"):
            t.add_column(col)
        geometry(geo, t)
        console.print(t)
    rows: list = []
    if args.recordings.is_dir():
        independent(args.recordings, rows)
    else:
        console.print(f"{args.recordings}: no recordings, left out")
    for seed in (int(s) for s in args.sim_seeds.split(",") if s.strip()):
        simulator(seed, args.spacing, args.fine, rows)
        console.print(f"simulator seed {seed} done", highlight=False)
    report(rows)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
