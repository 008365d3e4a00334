"""Camera calibration on real photos: insitu against OpenCV's own standard flow.

Per view: which detectors find the board (insitu's sector-based SB and classic, OpenCV's
standard ``findChessboardCorners``), the one insitu keeps, its corners and per-view RMS. Then
fx, fy, cx, cy and the RMS of ``calibrate_photos`` and of OpenCV's flow (classic detector,
``cornerSubPix`` with an 11 × 11 half-window, ``calibrateCamera``) on the same photos. Default:
OpenCV's 13 ``left*.jpg`` samples (9 × 6 inner corners; OpenCV's result fx ≈ 536.07 px).

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
console = Console(width=130)


def opencv_flow(images: list[np.ndarray], cols: int, rows: int, square: float):
    """OpenCV's tutorial flow: (found per image, rms, K)."""
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    found, pts = [], []
    for img in images:
        ok, c = cv2.findChessboardCorners(img, (cols, rows), None)
        found.append(bool(ok))
        if ok:
            pts.append(cv2.cornerSubPix(img, c, (11, 11), (-1, -1), crit))
    rms, K, *_ = cv2.calibrateCamera([obj] * len(pts), pts, images[0].shape[::-1], None, None)
    return found, float(rms), K


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
    t0 = time.perf_counter()
    cv_found, cv_rms, cv_K = opencv_flow(images, board.cols, board.rows, board.square_mm)
    t_cv = time.perf_counter() - t0

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
    for name, n, k, rms, dt in (("insitu", int(cal.residuals["views_used"]), K, cal.rms_px, t_ours),
                                ("OpenCV standard flow", sum(cv_found), cv_K, cv_rms, t_cv)):
        r.add_row(name, f"{n} of {len(files)}", f"{k[0, 0]:.2f}", f"{k[1, 1]:.2f}",
                  f"{k[0, 2]:.2f}", f"{k[1, 2]:.2f}", f"{rms:.4f}",
                  f"{100 * (k[0, 0] / OPENCV_FX - 1):+.2f} %", f"{dt:.2f}")
    console.print(r)
    if cal.std_intrinsics:
        console.print("insitu 1σ fx fy cx cy: " + "  ".join(f"{s:.2f}" for s in cal.std_intrinsics[:4]))


if __name__ == "__main__":
    main()
