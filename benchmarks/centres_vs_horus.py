"""The scan's line centres side by side with Horus's laser segmentation, one core, same frames.

Horus (bq/horus, GPL-2.0, the Ciclop scanner's software) finds a laser line's centres by
``LaserSegmentation.compute_2d_points`` (src/horus/engine/algorithms/laser_segmentation.py):
red channel, threshold to zero, box blur, threshold again, a window of ±``window`` px about
each row's maximum, the centre of mass per row, then its segmented Gaussian filter (SGF), with
its profile's scanning defaults (threshold 50, blur 2 → 5 × 5, window 8, SGF). Its code is not
in insitu: this script imports it from the Horus checkout given as its argument (a clone, or a
bare git directory such as the ``fetch`` tool's mirror, whose ``src/horus`` is unpacked into a
temporary folder), with the two Python 2 names Horus needs (``xrange``, module ``md5``) supplied.
Horus's camera is mounted with the line across its rows; ours runs along the rows for a line
along y, so Horus gets each frame transposed (before the clock starts: a mounting, not work).

insitu: exactly what a scan runs per frame (:class:`~insitu.reconstruct.scan.ScanReconstructor`):
the band the commanded line can fall in over the head's focus range
(:func:`~insitu.reconstruct.plane.line_band`) and :func:`~insitu.vision.extract.extract_centres`
with the default settings (Steger, the along-line window of issue 11's robustness) in it; the
same in the narrower band of the heights a survey measured (as ``produce`` with a recipe's
``scan.survey_mm`` searches its lines, :mod:`insitu.services.survey`: eight frames spread
over the recording, or eight lines 8 mm apart over the simulated part, reconstructed by
Method 1, their heights padded by ``HEIGHT_PAD_MM``); and, for reference, the same
extraction over the whole frame (no band).

Frames: 2448 × 2048 uint8 — the independent recordings (another renderer,
``shared/recordings``: the two scans, frames spread over each) and our simulator's (the step
block, the arc and the freeform part; rig seeds and exposures varied). The methods alternate on
each frame, round after round, so the machine's load falls on both alike; the table gives the
median process CPU time per frame (one thread: OMP/OpenCV set to 1, the process pinned to one
core) and the wall time beside it.

Run: nice -n 10 .venv/bin/python benchmarks/centres_vs_horus.py HORUS [--recordings DIR]
         [--frames 4] [--sim 6] [--rounds 5]
     HORUS: a clone of https://github.com/bq/horus, or its bare git directory.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core

import argparse  # noqa: E402
import builtins  # noqa: E402
import hashlib  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import types  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

from insitu.formats.sequence import Sequence  # noqa: E402
from insitu.reconstruct.plane import line_band, line_runs_along_rows  # noqa: E402
from insitu.reconstruct.scan import ScanReconstructor  # noqa: E402
from insitu.services.common import camera_model  # noqa: E402
from insitu.services.survey import HEIGHT_PAD_MM  # noqa: E402
from insitu.sim.render import NOMINAL_EXPOSURE_MS  # noqa: E402
from insitu.sim.rig import NOMINAL_HEAD, default_rig  # noqa: E402
from insitu.sim.workpieces import make_workpiece  # noqa: E402
from insitu.sim.world import SimWorld  # noqa: E402
from insitu.vision.extract import CentreSettings, extract_centres  # noqa: E402

cv2.setNumThreads(1)
DEFAULT_RECORDINGS = Path(__file__).resolve().parents[2] / "shared" / "recordings"
SEGMENTATION = Path("horus/engine/algorithms/laser_segmentation.py")
HORUS_DEFAULTS = {"red_channel": "R (RGB)", "threshold_enable": True, "threshold_value": 50,
                  "blur_enable": True, "blur_value": 2, "window_enable": True,
                  "window_value": 8, "refinement_method": "SGF"}
"""Horus's profile defaults for scanning (src/horus/util/profile.py, ``*_scanning``)."""


def horus_source(path: Path, tmp: Path) -> Path:
    """The folder holding Horus's ``horus`` package: ``path/src`` or ``path`` of a checkout,
    else ``src/horus`` unpacked from ``path`` as a (bare) git directory into ``tmp``."""
    for root in (path / "src", path):
        if (root / SEGMENTATION).is_file():
            return root
    if (path / "HEAD").is_file() or (path / ".git").exists():
        archive = subprocess.run(["git", f"--git-dir={path}", "archive", "HEAD", "src/horus"],
                                 capture_output=True, check=False)
        if archive.returncode == 0:
            subprocess.run(["tar", "-x", "-C", str(tmp)], input=archive.stdout, check=True)
            if (tmp / "src" / SEGMENTATION).is_file():
                return tmp / "src"
    raise SystemExit(f"{path}: no Horus checkout ({SEGMENTATION} not found); clone "
                     "https://github.com/bq/horus and give its folder")


def horus_segmentation(src: Path, width: int, height: int):
    """Horus's LaserSegmentation singleton, set to its scanning defaults for frames of
    ``width`` × ``height`` (Horus's own image size: the transposed frame's)."""
    builtins.xrange = range                                        # Python 2 names Horus uses
    md5 = types.ModuleType("md5")
    md5.new = hashlib.md5
    sys.modules.setdefault("md5", md5)
    sys.path.insert(0, str(src))
    from horus.engine.algorithms.laser_segmentation import LaserSegmentation
    from horus.engine.calibration.calibration_data import CalibrationData
    CalibrationData().set_resolution(width, height)
    seg = LaserSegmentation()
    for name, value in HORUS_DEFAULTS.items():
        getattr(seg, f"set_{name}")(value)
    return seg


def recorded(root: Path, per_scan: int) -> list[dict]:
    """``per_scan`` frames spread over each scan recording under ``root``, with what the scan
    needs to search them (camera, head, commanded line)."""
    out = []
    for seq_json in sorted(root.glob("*/sequence.json")):
        seq = Sequence.open(seq_json.parent)
        if seq.kind != "scan":
            continue
        cam, head = camera_model(seq.camera), seq.scan_head
        spread = np.linspace(0, len(seq) - 1, 8).round().astype(int)
        z = survey_heights(cam, head.pivot_height_mm, tuple(head.z_range_mm),
                           [(seq.read_frame(int(i)), *commanded(seq, i)) for i in spread])
        for i in np.linspace(0, len(seq) - 1, per_scan).round().astype(int):
            out.append(dict(source=f"recordings: {seq_json.parent.name}",
                            image=seq.read_frame(int(i)), camera=cam,
                            pivot=head.pivot_height_mm, z_range=tuple(head.z_range_mm),
                            survey_z=z, line=commanded(seq, i)))
    return out


def commanded(seq: Sequence, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Frame ``i``'s commanded line (start, end) mm."""
    f = seq.spec.frames[int(i)]
    return np.asarray(f.line.start, float), np.asarray(f.line.end, float)


def survey_heights(camera, pivot: float, z_range: tuple[float, float], frames: list
                   ) -> tuple[float, float]:
    """The heights (low, high) mm a survey of ``frames`` ((image, start, end) each) measures
    (Method 1), padded by HEIGHT_PAD_MM and kept within ``z_range``: the band a scan with a
    survey searches its lines in."""
    rec = ScanReconstructor(camera, pivot, z_range_mm=z_range)
    for k, (image, start, end) in enumerate(frames):
        rec.add(k, image, start, end)
    lo, hi = rec.heights()
    return max(lo - HEIGHT_PAD_MM, z_range[0]), min(hi + HEIGHT_PAD_MM, z_range[1])


SIM_SETTINGS = [("step-block", 0, 1.0), ("arc", 1, 0.5), ("freeform", 2, 2.0)]
"""(part, rig seed, exposure × nominal) of the simulated frames."""


def simulated(n: int) -> list[dict]:
    """``n`` frames of our simulator, spread over :data:`SIM_SETTINGS` and lines x = −8 … 8 mm."""
    out = []
    per = max(1, -(-n // len(SIM_SETTINGS)))
    for part, seed, gain in SIM_SETTINGS:
        rig = default_rig(seed=seed)
        r = SimWorld(rig, parts=[make_workpiece(part)], seed=seed).renderer()
        ends = [(np.array([x, -45.0]), np.array([x, 45.0])) for x in np.arange(-28, 29, 8)]
        z = survey_heights(rig.operator.camera, NOMINAL_HEAD.pivot_height_mm,
                           tuple(NOMINAL_HEAD.z_range_mm),
                           [(r.line_frame(a, b, exposure_ms=gain * NOMINAL_EXPOSURE_MS), a, b)
                            for a, b in ends])
        for x in np.linspace(-8, 8, per):
            start, end = np.array([x, -45.0]), np.array([x, 45.0])
            img = r.line_frame(start, end, exposure_ms=gain * NOMINAL_EXPOSURE_MS)
            out.append(dict(source=f"simulator: {part}, seed {seed}, exposure ×{gain:g}",
                            image=img, camera=rig.operator.camera,
                            pivot=NOMINAL_HEAD.pivot_height_mm,
                            z_range=tuple(NOMINAL_HEAD.z_range_mm), survey_z=z,
                            line=(start, end)))
    return out[:n] if n else []


def ours(frame: dict, banded: bool = True, heights: str = "z_range"):
    """The scan's centres of one frame (ScanReconstructor.add's extraction), in the band of
    the frame's ``heights`` ("z_range": the focus range; "survey_z": a survey's)."""
    start, end = frame["line"]
    band, upper = None, 0
    if banded:
        rows, lo, hi, upper = line_band(frame["camera"], start, end, frame["pivot"],
                                        frame[heights])
        band = (lo, hi)
    else:
        rows = line_runs_along_rows(frame["camera"], start, end)
    return extract_centres(frame["image"], CentreSettings(), band, rows, upper)


def measure(frames: list[dict], methods: dict, rounds: int) -> dict:
    """{(method, source): ([cpu s], [wall s], [points])}, the methods alternating per frame."""
    res: dict = {}
    for k in range(rounds):
        for frame in frames:
            names = list(methods) if k % 2 == 0 else list(methods)[::-1]
            for name in names:
                fn, arg = methods[name](frame)
                c0, w0 = time.process_time(), time.perf_counter()
                out = fn(arg)
                c1, w1 = time.process_time(), time.perf_counter()
                r = res.setdefault((name, frame["source"].split(":")[0]), ([], [], []))
                r[0].append(c1 - c0)
                r[1].append(w1 - w0)
                r[2].append(len(out[0][0]) if isinstance(out, tuple) else len(out))
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("horus", type=Path, help="Horus checkout or bare git directory")
    ap.add_argument("--recordings", type=Path, default=DEFAULT_RECORDINGS)
    ap.add_argument("--frames", type=int, default=4, help="frames per recorded scan")
    ap.add_argument("--sim", type=int, default=6, help="simulated frames")
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args()
    frames = recorded(a.recordings, a.frames) + simulated(a.sim)
    if not frames:
        raise SystemExit("no frames: give --recordings or --sim")
    H, W = frames[0]["image"].shape
    with tempfile.TemporaryDirectory() as tmp:
        seg = horus_segmentation(horus_source(a.horus, Path(tmp)), H, W)
    for f in frames:
        f["horus"] = np.ascontiguousarray(f["image"].T)            # Horus's line: across rows
    methods = {
        "Horus (threshold, blur, window, centre of mass, SGF)":
            lambda f: (seg.compute_2d_points, f["horus"]),
        "insitu default, the scan's band (what a scan runs)": lambda f: (ours, f),
        "insitu default, the band of a survey's heights": lambda f: (
            lambda g: ours(g, heights="survey_z"), f),
        "insitu default, whole frame": lambda f: (lambda g: ours(g, banded=False), f),
    }
    res = measure(frames, methods, a.rounds)
    t = Table(title=f"line centres, {W} × {H} uint8, one core, median over {a.rounds} rounds")
    for col in ("frames", "method", "ms/frame CPU", "frames/s CPU", "ms wall", "× Horus",
                "points/frame"):
        t.add_column(col, justify="left" if col in ("frames", "method") else "right")
    for src in dict.fromkeys(k[1] for k in res):
        n = sum(f["source"].startswith(src) for f in frames)
        base = np.median(res[(next(iter(methods)), src)][0])
        for name in methods:
            cpu, wall, pts = res[(name, src)]
            t.add_row(f"{src} ({n})", name, f"{np.median(cpu) * 1e3:.2f}",
                      f"{1 / np.median(cpu):.0f}", f"{np.median(wall) * 1e3:.2f}",
                      f"{base / np.median(cpu):.1f}",
                      f"{np.mean(pts):.0f}")
    Console(width=140).print(t)
    for f in dict.fromkeys((f["source"], f["z_range"], f["survey_z"]) for f in frames):
        print(" ", f[0], "focus range {:g} … {:g} mm".format(*f[1]),
              "survey's heights {:.1f} … {:.1f} mm".format(*f[2]))


if __name__ == "__main__":
    main()
