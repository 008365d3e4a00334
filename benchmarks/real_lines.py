"""Line centres on real laser-line photographs: the automatic direction, and each centre
method's RMS distance to the fitted laser plane against a plain threshold centre of mass.

Data (not in this repository; the source repository has no licence): the desktop 3-D scanner
of github.com/srv/desktop_3d_scanner, folder ``python/calib_images/Laser/Calibracio17_07``:
121 colour JPEGs, 640 × 480, a green laser line on a hand-held checkerboard (8 × 6 inner
corners, 40 mm squares) in front of a cluttered room; the board is found in 91. Camera: that
repository's ``python/calibration4.yaml`` (copied below).

Per image where the board is found: its pose (solvePnP); each method's centres on the board
(the line runs down the rows: one centre per image row, direction given) are cast as rays
onto the board plane, in mm in the camera frame. The laser is fixed to the camera, so every
point of every image lies on one plane: fitted (least squares after dropping points > 5
robust σ, counted as outliers, iterated) per method, the RMS of the kept points' distances
is the method's figure. Baseline, on the same scan lines as each method: the centre of mass
of the gray values above half-way between the line's background and its peak, within ±12 px
of the shared detection's peak (:func:`insitu.vision.detect.detect`). The true direction of an
image: that of the laser plane's intersection with its board plane, projected.

Run: .venv/bin/python benchmarks/real_lines.py FOLDER
"""

from __future__ import annotations

import argparse
import glob
import os

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.vision.centres import as_gray, line_centres, line_direction
from insitu.vision.detect import detect, gather

K = np.array([[620.2678375549896, 0.0, 322.94579652113293],
              [0.0, 618.61305587237, 239.42135627438046], [0.0, 0.0, 1.0]])
DIST = np.array([0.11369913583372294, -0.193716412669678, -0.0011143493279290875,
                 -0.0021599136353324592, -0.03519351082447173])
PATTERN, SQUARE = (8, 6), 40.0          # inner corners (cols, rows); mm
MARGIN = 3 * SQUARE                     # the board's white margin (not published), mm
AREA = (-MARGIN, (PATTERN[0] - 1) * SQUARE + MARGIN, -MARGIN, (PATTERN[1] - 1) * SQUARE + MARGIN)
WINDOW = 12
GATE = 3.0              # mm off the reference plane: not on the board (room, hand), dropped

METHODS = {                               # name: (method, keywords)
    "gray, Eq. 7 (paper, k = 0.5)": ("gray", {"k": 0.5, "extend_ends": False}),
    "gray, background (k = 0.5)": ("gray", {"k": 0.5, "background": True}),
    "gaussian": ("gaussian", {}),
    "steger": ("steger", {}),
}


def board_pose(bgr):
    """(R (3, 3), t (3,) mm) of the board in the camera frame, or None if not found."""
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    ok, corners = cv2.findChessboardCorners(gray, PATTERN, None)
    if not ok:
        return None
    corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1),
                               (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3))
    obj = np.zeros((PATTERN[0] * PATTERN[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:PATTERN[0], 0:PATTERN[1]].T.reshape(-1, 2) * SQUARE
    _, rvec, tvec = cv2.solvePnP(obj, corners, K, DIST)
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def on_board(uv, R, t):
    """Rays through pixels uv (N, 2) onto the board plane: (N, 3) mm camera frame, and the
    (N,) mask of points inside the board's area (checkers and margin, AREA)."""
    if len(uv) == 0:
        return np.zeros((0, 3)), np.zeros(0, bool)
    ray = cv2.undistortPoints(uv.reshape(-1, 1, 2).astype(np.float64), K, DIST).reshape(-1, 2)
    ray = np.column_stack([ray, np.ones(len(ray))])
    n = R[:, 2]
    X = ray * ((n @ t) / (ray @ n))[:, None]
    b = (X - t) @ R                                              # board coordinates, mm
    inside = (b[:, 0] > AREA[0]) & (b[:, 0] < AREA[1]) & (b[:, 1] > AREA[2]) & (b[:, 1] < AREA[3])
    return X, inside


def threshold_com(gray_t):
    """Plain threshold centre of mass per scan line of ``gray_t`` (line along its rows):
    (scan lines (n,), centre (n,) px) — weights g above (bg + peak)/2 within ±WINDOW."""
    det = detect(gray_t, window=WINDOW)
    rows = np.arange(-WINDOW, WINDOW + 1)[:, None]
    g, inside = gather(det.pre, det.row[None, :] + rows, det.cols)
    g[(g <= (det.bg + det.gmax) / 2) | ~inside] = 0
    return det.cols, det.row + (g * rows).sum(axis=0) / np.maximum(g.sum(axis=0), 1e-9)


def plane_fit(X, sigmas=5.0):
    """Plane through X (N, 3) mm by least squares, points > sigmas robust σ off dropped
    (iterated): (unit normal (3,), offset mm), n·x = offset."""
    keep = np.ones(len(X), bool)
    for _ in range(20):
        c = X[keep].mean(axis=0)
        n = np.linalg.svd(X[keep] - c, full_matrices=False)[2][2]
        d = np.abs((X - c) @ n)
        new = d <= sigmas * 1.4826 * np.median(d[keep])
        if (new == keep).all():
            break
        keep = new
    return n, float(n @ c)


def rms_to_plane(X):
    """RMS distance (mm) of X (N, 3) to its least-squares plane."""
    return float(np.linalg.svd(X - X.mean(axis=0), full_matrices=False)[1][2] / np.sqrt(len(X)))


def true_direction(R, t, n, d):
    """"rows"/"cols": the projected direction of the laser plane ∩ board plane."""
    nb = R[:, 2]
    a = np.cross(n, nb)
    p0 = np.linalg.lstsq(np.stack([n, nb]), np.array([d, nb @ t]), rcond=None)[0]
    centre = t + R @ np.array([AREA[1] / 2, AREA[3] / 2, 0.0])
    p0 = p0 + a * ((centre - p0) @ a) / (a @ a)                  # near the board's centre
    uv = cv2.projectPoints(np.stack([p0 - 50 * a, p0 + 50 * a]), np.zeros(3), np.zeros(3), K,
                           DIST)[0].reshape(2, 2)
    du, dv = np.abs(uv[1] - uv[0])
    return "rows" if du >= dv else "cols"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", help="folder of the photographs (*.jpg)")
    folder = ap.parse_args().folder
    files = sorted(glob.glob(os.path.join(folder, "*.jpg")))
    if not files:
        raise SystemExit(f"{folder}: no *.jpg (see this script's docstring for the data)")
    views, pts, base = [], {m: [] for m in METHODS}, {m: [] for m in METHODS}
    for f in files:
        bgr = cv2.imread(f)
        pose = board_pose(bgr)
        if pose is None:
            continue
        gray = as_gray(bgr)                                        # channel "auto"
        views.append((f, pose, line_direction(gray)))
        rows_b, cen_b = threshold_com(cv2.transpose(gray))
        ref = dict(zip(rows_b.tolist(), cen_b))
        for name, (method, kw) in METHODS.items():
            c = line_centres(gray, method, "cols", **kw)
            common = np.array([r in ref for r in np.round(c.v).astype(int).tolist()], bool)
            uv = c.uv[common]
            uvb = np.column_stack([[ref[int(r)] for r in np.round(uv[:, 1])], uv[:, 1]])
            X, ok = on_board(uv, *pose)
            Xb, okb = on_board(uvb, *pose)
            both = ok & okb
            pts[name].append(X[both])
            base[name].append(Xb[both])
    ref = plane_fit(np.concatenate([np.concatenate(p[m]) for p in (pts, base) for m in METHODS]))
    console = Console(width=120)
    table = Table(title=f"{len(views)} of {len(files)} photographs with the board found "
                        f"({folder}); RMS distance to the fitted laser plane, mm")
    for col in ("method", "scan lines", "off the board", "RMS mm", "threshold CoM RMS mm",
                "better by"):
        table.add_column(col, justify="left" if col == "method" else "right")
    for name in METHODS:
        X, Xb = np.concatenate(pts[name]), np.concatenate(base[name])
        near = ((np.abs(X @ ref[0] - ref[1]) <= GATE) & (np.abs(Xb @ ref[0] - ref[1]) <= GATE))
        r, rb = rms_to_plane(X[near]), rms_to_plane(Xb[near])
        table.add_row(name, str(near.sum()), str((~near).sum()), f"{r:.3f}", f"{rb:.3f}",
                      f"{100 * (1 - r / rb):.0f} %")
    console.print(table)
    right = sum(true_direction(*pose, *ref) == auto for _, pose, auto in views)
    truths = {true_direction(*pose, *ref) for _, pose, _ in views}
    console.print(f"automatic direction right on {right} of {len(views)} "
                  f"({100 * right / max(len(views), 1):.1f} %); true directions: "
                  f"{', '.join(sorted(truths))} (laser plane ∩ board plane, projected)")
    console.print(f"points: centres on the board's area whose method and baseline points are "
                  f"both ≤ {GATE} mm from the laser plane fitted to all (else off the board); "
                  "RMS: each set about its own least-squares plane")


if __name__ == "__main__":
    main()
