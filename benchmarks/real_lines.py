"""Line centres on real laser-line photographs (benchmarks/real_sets.py): how often the stripe is
found where it crosses the board, how often a centre lies elsewhere, and each method's RMS
distance to its own laser plane against a naive centre of mass on the same scan lines.

Each photograph is measured as ``insitu centres`` measures anyone's photograph
(:func:`~insitu.vision.centres.photo_centres`: the method's defaults, the channel and the
direction found from the image, no geometry given); with
``--background`` the set's laser-off photograph is subtracted (sets that have one).

Truth. The board's pose in each photograph (found, or published) and the laser plane (the
published one or the authors' own points', else fitted robustly to every method's points on
the boards,
in mm in the camera frame: the laser is fixed to the camera) give the stripe's true course in
the image: the plane ∩ the board's plane, projected through the camera's distortion. A scan
line (a column of an image whose stripe runs along the rows, a row where it runs down) crosses
the board where that course lies inside the board's ``area``.

Per method, over the board's scan lines: found — a centre within 5 px of the true course;
wrong — a centre more than 5 px off it. RMS at equal coverage: on the (photograph, scan line)
pairs where both the method and the baseline found the stripe, each one's points are cast onto
the board plane and fitted with their own least-squares plane; the figure is the RMS distance
to it (the boards' pose errors are in both alike) and the ratio method / baseline.

Baseline, the naive centre of mass: per scan line of the laser's own channel (the set says
which), the pixels within ±8 px of the line's maximum that reach 0.8 of it, weighted by their
value. Nothing else: no validity test, no filter.

Hold-out: ``--half first`` scores the first half of each set's photographs with a board pose
(in the order ``files`` gives them, :func:`half`), ``--half second`` the rest; the truth's
plane, where it is fitted, is fitted on all of them. real_sets.TUNED says which half of which
set the defaults were tuned on.

Run: .venv/bin/python benchmarks/real_lines.py DATA [--sets desktop,…] [--background]
[--half first|second|all]
"""

from __future__ import annotations

import argparse
import os
import sys

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from real_sets import SETS, TUNED, PhotoSet  # noqa: E402

from insitu.vision.centres import CENTRE_METHODS, UncertainLine, photo_centres  # noqa: E402

NAIVE_FRACTION, NAIVE_WINDOW = 0.8, 8
RIGHT_PX = 5.0
METHODS = tuple(CENTRE_METHODS)


def naive_com(channel: np.ndarray, along_rows: bool) -> np.ndarray:
    """(n_scan_lines,) centre of mass per scan line (NAIVE_FRACTION of the line's maximum,
    ±NAIVE_WINDOW px), across the line: per column for a stripe along the rows."""
    g = channel.astype(np.float64)
    g = g if along_rows else g.T                                 # (cross, scan)
    peak = np.argmax(g, axis=0)
    offs = np.arange(-NAIVE_WINDOW, NAIVE_WINDOW + 1)[:, None]
    rows = np.clip(peak[None, :] + offs, 0, g.shape[0] - 1)
    vals = g[rows, np.arange(g.shape[1])[None, :]]
    vals[vals < NAIVE_FRACTION * vals.max(axis=0)] = 0
    return (vals * rows).sum(axis=0) / np.maximum(vals.sum(axis=0), 1e-9)


def rays_to_board(uv, K, dist, R, t) -> np.ndarray:
    """Pixels uv (N, 2) cast onto the board plane: (N, 3) mm, camera frame."""
    if len(uv) == 0:
        return np.zeros((0, 3))
    ray = cv2.undistortPoints(uv.reshape(-1, 1, 2).astype(np.float64), K, dist).reshape(-1, 2)
    ray = np.column_stack([ray, np.ones(len(ray))])
    n = R[:, 2]
    return ray * ((n @ t) / (ray @ n))[:, None]


def true_course(s: PhotoSet, R, t, plane, shape):
    """The stripe's true course in one photograph: (along_rows, scan lines (m,) int, true
    cross coordinate (m,) px) over the scan lines where it crosses the board's area; None
    when it does not cross it."""
    n, d = plane
    nb = R[:, 2]
    a = np.cross(n, nb)
    if np.linalg.norm(a) < 1e-9:
        return None
    p0 = np.linalg.lstsq(np.stack([n, nb]), np.array([d, nb @ t]), rcond=None)[0]
    # the course in board coordinates: p0 + s·a → b = Rᵀ(x − t); keep s inside the area
    b0, b1 = R.T @ (p0 - t), R.T @ a
    x0, x1, y0, y1 = s.area
    lo, hi = -np.inf, np.inf
    for k, (c0, c1) in enumerate(((x0, x1), (y0, y1))):
        if abs(b1[k]) < 1e-12:
            if not c0 <= b0[k] <= c1:
                return None
            continue
        e = sorted(((c0 - b0[k]) / b1[k], (c1 - b0[k]) / b1[k]))
        lo, hi = max(lo, e[0]), min(hi, e[1])
    if not hi > lo:
        return None
    X = p0 + np.linspace(lo, hi, 2000)[:, None] * a
    uv = cv2.projectPoints(X, np.zeros(3), np.zeros(3), s.K, s.dist)[0].reshape(-1, 2)
    du, dv = np.ptp(uv, axis=0)
    along_rows = du >= dv
    scan, cross = (uv[:, 0], uv[:, 1]) if along_rows else (uv[:, 1], uv[:, 0])
    order = np.argsort(scan)
    lines = np.arange(int(np.ceil(scan.min())), int(np.floor(scan.max())) + 1)
    true = np.interp(lines, scan[order], cross[order])
    H, W = shape
    inside = (lines >= 0) & (lines < (W if along_rows else H)) & (true >= 3) & \
        (true <= (H if along_rows else W) - 4)
    return along_rows, lines[inside], true[inside]


def per_scan_line(uv: np.ndarray, along_rows: bool) -> dict[int, float]:
    """{scan line: cross coordinate} of centres uv (N, 2); a scan line with several keeps the
    first."""
    scan, cross = (uv[:, 0], uv[:, 1]) if along_rows else (uv[:, 1], uv[:, 0])
    out: dict[int, float] = {}
    for k, x in zip(np.round(scan).astype(int).tolist(), cross.tolist()):
        out.setdefault(k, x)
    return out


def plane_fit(X, sigmas=5.0):
    """Robust least-squares plane of X (N, 3) (points > sigmas robust σ off dropped,
    iterated): (unit normal, offset mm)."""
    keep = np.ones(len(X), bool)
    for _ in range(30):
        c = X[keep].mean(axis=0)
        n = np.linalg.svd(X[keep] - c, full_matrices=False)[2][2]
        d = np.abs((X - c) @ n)
        new = d <= sigmas * 1.4826 * np.median(d[keep])
        if (new == keep).all():
            break
        keep = new
    return n, float(n @ c)


def rms_to_own_plane(X) -> float:
    return float(np.linalg.svd(X - X.mean(axis=0), full_matrices=False)[1][2] / np.sqrt(len(X)))


def centres_or_none(bgr, method, laser_off) -> np.ndarray:
    """photo_centres' uv (N, 2), or (0, 2) for a photograph it refuses (UncertainLine)."""
    try:
        return photo_centres(bgr, method, laser_off=laser_off).uv
    except UncertainLine:
        return np.zeros((0, 2))


def half(items: list, which: str) -> list:
    """The first half of ``items`` (the first ⌈n/2⌉), the second (the rest) or all."""
    n = (len(items) + 1) // 2
    return {"first": items[:n], "second": items[n:], "all": items}[which]


def measure(s: PhotoSet, root: str, background: bool):
    """Centres of every photograph with a board pose: [(file, pose, shape, {name: uv})], the
    naive baseline under "naive" (its uv for both directions: "naive rows", "naive cols")."""
    out = []
    for f in s.files(root):
        bgr = cv2.imread(f, cv2.IMREAD_COLOR)
        pose = s.pose(f, bgr)
        if pose is None:
            continue
        bg = None
        if background and s.background(f) is not None:
            bg = cv2.imread(s.background(f), cv2.IMREAD_COLOR)
        found = {m: centres_or_none(bgr, m, bg) for m in METHODS}
        ch = bgr[:, :, "bgr".index(s.laser)]
        for along_rows in (True, False):
            cen = naive_com(ch, along_rows)
            k = np.arange(len(cen), dtype=np.float64)
            found["naive rows" if along_rows else "naive cols"] = (
                np.column_stack([k, cen]) if along_rows else np.column_stack([cen, k]))
        out.append((f, pose, bgr.shape[:2], found))
    return out


def reference_plane(s: PhotoSet, shots):
    """The published plane, else one fitted to every method's points inside the boards'
    areas."""
    if s.plane() is not None:
        return s.plane()
    pts = []
    for _, (R, t), _, found in shots:
        for uv in (found[m] for m in METHODS):
            X = rays_to_board(uv, s.K, s.dist, R, t)
            b = (X - t) @ R
            x0, x1, y0, y1 = s.area
            pts.append(X[(b[:, 0] > x0) & (b[:, 0] < x1) & (b[:, 1] > y0) & (b[:, 1] < y1)])
    return plane_fit(np.concatenate(pts))


def score(s: PhotoSet, shots, plane):
    """Per method: (board scan lines, found, wrong, {method: [(file, R, t, uv of method,
    uv of baseline)] on the pairs both found})."""
    rows = {m: [0, 0, 0] for m in (*METHODS, "naive")}
    pairs = {m: [] for m in METHODS}
    for _f, (R, t), shape, found in shots:
        course = true_course(s, R, t, plane, shape)
        if course is None:
            continue
        along_rows, lines, true = course
        truth = dict(zip(lines.tolist(), true.tolist()))
        naive = per_scan_line(found["naive rows" if along_rows else "naive cols"], along_rows)
        naive_ok = {k: x for k, x in naive.items() if k in truth and
                    abs(x - truth[k]) <= RIGHT_PX}
        for m in (*METHODS, "naive"):
            got = naive if m == "naive" else per_scan_line(found[m], along_rows)
            on = {k: x for k, x in got.items() if k in truth}
            right = {k: x for k, x in on.items() if abs(x - truth[k]) <= RIGHT_PX}
            r = rows[m]
            r[0] += len(truth)
            r[1] += len(right)
            r[2] += len(on) - len(right)
            if m != "naive":
                both = sorted(set(right) & set(naive_ok))
                uv = np.array([(k, right[k]) if along_rows else (right[k], k) for k in both],
                              float).reshape(-1, 2)
                uvb = np.array([(k, naive_ok[k]) if along_rows else (naive_ok[k], k)
                                for k in both], float).reshape(-1, 2)
                pairs[m].append((R, t, uv, uvb))
    return rows, pairs


def report(s: PhotoSet, root: str, background: bool, console: Console,
           which: str = "all") -> None:
    every = measure(s, root, background)
    if not every:
        console.print(f"{s.name}: no photographs with a board under {root} (see real_sets.py)")
        return
    plane = reference_plane(s, every)
    shots = half(every, which)
    rows, pairs = score(s, shots, plane)
    role = TUNED.get(s.name, "looked at, not held out")
    table = Table(title=f"{s.name} ({s.repo}; {which} half: {len(shots)} photographs with the "
                        f"board{', laser-off frame subtracted' if background else ''}; {role})")
    for col in ("method", "board scan lines", "found %", "wrong %", "photos without",
                "pairs", "RMS mm", "naive RMS mm", "ratio"):
        table.add_column(col, justify="left" if col == "method" else "right")
    for m in (*METHODS, "naive"):
        n, right, wrong = rows[m]
        cells = [m, str(n), f"{100 * right / max(n, 1):.1f}", f"{100 * wrong / max(n, 1):.2f}",
                 "" if m == "naive" else str(sum(not len(sh[3][m]) for sh in shots))]
        if m == "naive":
            table.add_row(*cells, "", "", "", "")
            continue
        X = np.concatenate([np.zeros((0, 3))] + [rays_to_board(uv, s.K, s.dist, R, t)
                                                 for R, t, uv, _ in pairs[m]])
        Xb = np.concatenate([np.zeros((0, 3))] + [rays_to_board(b, s.K, s.dist, R, t)
                                                  for R, t, _, b in pairs[m]])
        if len(X) <= 3:
            table.add_row(*cells, str(len(X)), "—", "—", "—")
            continue
        r, rb = rms_to_own_plane(X), rms_to_own_plane(Xb)
        table.add_row(*cells, str(len(X)), f"{r:.3f}", f"{rb:.3f}", f"{r / rb:.2f}")
    console.print(table)
    if s.plane() is not None and sum(len(found[m]) for *_, found in every for m in METHODS) > 3:
        own = reference_plane(PhotoSet(**{**s.__dict__, "plane": lambda: None}), every)
        angle = np.degrees(np.arccos(min(1.0, abs(float(own[0] @ s.plane()[0])))))
        console.print(f"the published plane and one fitted to the points: {angle:.2f}° apart")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("data", help="folder holding the sets' repositories (real_sets.py)")
    ap.add_argument("--sets", default=",".join(SETS), help="comma-separated: "
                    + ", ".join(SETS))
    ap.add_argument("--background", action="store_true",
                    help="subtract the set's laser-off photograph (sets that have one)")
    ap.add_argument("--half", choices=("first", "second", "all"), default="all",
                    help="score the first half of each set's photographs, the second, or all")
    a = ap.parse_args()
    console = Console(width=130)
    for name in a.sets.split(","):
        if name not in SETS:
            raise SystemExit(f"--sets: {name!r}: expected one of {', '.join(SETS)}")
        report(SETS[name], a.data, a.background, console, a.half)
    console.print(f"found: a centre within {RIGHT_PX:g} px of the true course on a scan line "
                  f"where it crosses the board; wrong: farther. RMS: on the pairs both the "
                  f"method and the naive centre of mass ({NAIVE_FRACTION:g} of the line's "
                  f"maximum, ±{NAIVE_WINDOW} px) found, each about its own plane. Photos "
                  f"without: photographs with no centre (none found, or refused: the line's "
                  f"laser colour no stronger than the colour fringes at the edges).")


if __name__ == "__main__":
    main()
