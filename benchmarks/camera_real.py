"""Camera calibration on real photos: insitu against OpenCV's own sample flows.

Per view: which detectors find the board (insitu's sector-based SB and classic, OpenCV's
standard ``findChessboardCorners``), the one insitu keeps, its corners and per-view RMS. Then
fx, fy, cx, cy and the RMS of ``calibrate_photos`` and of OpenCV's two sample flows on the same
photos — both classic detector, ``cornerSubPix``, ``calibrateCamera`` with default flags (5-term
distortion, k3 free), 9 × 6 inner corners; they differ in the refinement window:

- the Python tutorial (``tutorial_py_calibration``) and ``samples/cpp/calibration.cpp``:
  ``winSize`` (11, 11), a 23 × 23 px window (stopping at 0.001 px and 0.1 px: fx 536.07 px on
  the 13 ``left*.jpg``, the figure usually quoted, and 535.89);
- ``samples/python/calibrate.py``: ``winSize`` (5, 5), an 11 × 11 px window.

Then the window swept (fx and RMS against its half-size), how far each view's corners move
between the 11 × 11 and the 23 × 23 window, and the 23 × 23 flow without the views where they
move by more than 1 px. Default: OpenCV's 13 ``left*.jpg`` samples.

Run: .venv/bin/python benchmarks/camera_real.py [FOLDER] [--board 9x6x1]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.calibrate.camera import find_chessboard
from insitu.calibrate.photos import image_files, parse_board, read_grey
from insitu.services.camera import calibrate_photos

SAMPLES = Path(__file__).resolve().parents[1] / "tests/data/real/opencv-left"
OPENCV_FX = 536.07
_EPS = cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT
TUTORIAL = ("OpenCV tutorial, 23×23 window", 11, (_EPS, 30, 0.001))
CPP = ("OpenCV C++ sample, 23×23 window", 11, (_EPS, 30, 0.1))
PY = ("OpenCV Python sample, 11×11 window", 5, (_EPS, 30, 0.1))
console = Console(width=130)


def opencv_corners(images: list[np.ndarray], cols: int, rows: int, half: int, crit
                   ) -> list[np.ndarray | None]:
    """OpenCV's sample detection: classic detector, cornerSubPix with ``half`` (winSize)."""
    out = []
    for img in images:
        ok, c = cv2.findChessboardCorners(img, (cols, rows), None)
        out.append(cv2.cornerSubPix(img, c, (half, half), (-1, -1), crit) if ok else None)
    return out


def opencv_calibrate(corners: list[np.ndarray | None], cols: int, rows: int, square: float,
                     size: tuple[int, int]):
    """``calibrateCamera`` with OpenCV's default flags on the views found: (rms, K)."""
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    pts = [c for c in corners if c is not None]
    rms, K, *_ = cv2.calibrateCamera([obj] * len(pts), pts, size, None, None)
    return float(rms), K


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path, nargs="?", default=SAMPLES)
    ap.add_argument("--board", default="9x6x1", help="COLSxROWSxSQUARE_MM")
    args = ap.parse_args()
    board = parse_board(args.board)
    files = image_files(args.folder)
    images = [read_grey(p) for p in files]
    images = [im if im.dtype == np.uint8 else (im >> 8).astype(np.uint8) for im in images]
    size = (board.cols, board.rows)
    t0 = time.perf_counter()
    cal = calibrate_photos(args.folder, board)
    t_ours = time.perf_counter() - t0
    shape = images[0].shape[::-1]
    flows = {}
    for name, half, crit in (TUTORIAL, CPP, PY):
        t0 = time.perf_counter()
        corners = opencv_corners(images, board.cols, board.rows, half, crit)
        flows[name] = (corners, *opencv_calibrate(corners, board.cols, board.rows,
                                                  board.square_mm, shape),
                       time.perf_counter() - t0)
    cv_found = [c is not None for c in flows[TUTORIAL[0]][0]]

    t = Table(title=f"{args.folder}: {board.describe()}, per view")
    for c in ("view", "SB", "classic", "OpenCV flow", "kept", "corners", "used", "RMS px"):
        t.add_column(c, justify="left" if c in ("view", "kept") else "right")
    yes = {True: "found", False: "—"}
    for img, v, cv_ok in zip(images, cal.views, cv_found):
        sb, classic = (find_chessboard(img, size, d) is not None for d in ("sb", "classic"))
        t.add_row(v["file"], yes[sb], yes[classic], yes[cv_ok], v["detector"] or "—",
                  str(board.cols * board.rows) if v["detector"] else "0",
                  "yes" if v["used"] else v["reason"],
                  f"{v['rms_px']:.3f}" if v["rms_px"] is not None else "")
    console.print(t)

    r = Table(title="result")
    for c in ("", "views", "fx", "fy", "cx", "cy", "RMS px", "fx vs 536.07", "time s"):
        r.add_column(c, justify="right" if c else "left")
    K = np.array(cal.camera.K)
    rows = [("insitu", int(cal.residuals["views_used"]), K, cal.rms_px, t_ours)]
    rows += [(name, sum(c is not None for c in cs), k, rms, dt)
             for name, (cs, rms, k, dt) in flows.items()]
    for name, n, k, rms, dt in rows:
        r.add_row(name, f"{n} of {len(files)}", f"{k[0, 0]:.2f}", f"{k[1, 1]:.2f}",
                  f"{k[0, 2]:.2f}", f"{k[1, 2]:.2f}", f"{rms:.4f}",
                  f"{100 * (k[0, 0] / OPENCV_FX - 1):+.2f} %", f"{dt:.2f}")
    console.print(r)
    if cal.std_intrinsics:
        console.print("insitu 1σ fx fy cx cy: " + "  ".join(f"{s:.2f}" for s in cal.std_intrinsics[:4]))
    window_study(images, files, board, shape, flows)


def window_study(images, files, board, shape, flows) -> None:
    """fx and RMS of OpenCV's flow against the window; where the 23 × 23 window moves corners."""
    crit = TUTORIAL[2]
    w = Table(title="OpenCV's flow against the cornerSubPix window (winSize = half-size)")
    for c in ("winSize", "window px", "fx", "fy", "RMS px"):
        w.add_column(c, justify="right")
    for half in (3, 5, 7, 9, 11, 13):
        rms, k = opencv_calibrate(opencv_corners(images, board.cols, board.rows, half, crit),
                                  board.cols, board.rows, board.square_mm, shape)
        w.add_row(str(half), f"{2 * half + 1}", f"{k[0, 0]:.2f}", f"{k[1, 1]:.2f}", f"{rms:.4f}")
    console.print(w)
    big, small = flows[TUTORIAL[0]][0], flows[PY[0]][0]
    v = Table(title="corners moved from the 11×11 to the 23×23 window, px")
    for c in ("view", "min spacing px", "mean", "max", "worst corner (col, row)"):
        v.add_column(c, justify="left" if c == "view" else "right")
    moved = []
    for f, a, b in zip(files, small, big):
        if a is None or b is None:
            continue
        a, b = a.reshape(-1, 2), b.reshape(-1, 2)
        g = a.reshape(board.rows, board.cols, 2)
        spacing = min(np.linalg.norm(np.diff(g, axis=ax), axis=2).min() for ax in (0, 1))
        d = np.linalg.norm(b - a, axis=1)
        worst = int(d.argmax())
        v.add_row(f.name, f"{spacing:.1f}", f"{d.mean():.3f}", f"{d.max():.3f}",
                  f"({worst % board.cols}, {worst // board.cols})")
        moved.append(d.max() > 1.0)
    console.print(v)
    kept = [c if not m else None for c, m in zip(big, moved)]
    rms, k = opencv_calibrate(kept, board.cols, board.rows, board.square_mm, shape)
    console.print(f"23×23 flow without the {sum(moved)} views whose corners it moves by > 1 px: "
                  f"fx {k[0, 0]:.2f} fy {k[1, 1]:.2f} cx {k[0, 2]:.2f} cy {k[1, 2]:.2f} "
                  f"RMS {rms:.4f} px")


if __name__ == "__main__":
    main()
