"""Camera calibration, alignment to the scan head, and pose recalibration after a camera move,
on the simulated rig (full-size frames unless --binning), scored against truth.json.

(a) Intrinsics: checkerboard views of the true camera (``record_camera_calibration`` with
    the simulated board: the checkerboard views plus the alignment frames),
    calibrated by ``calibrate_camera``: fx, fy, cx, cy and distortion against the truth, the
    focal error in % (target 0.1 %), what the intrinsic error is in pixels over the image, the
    reprojection RMS and the time.
(b) Alignment (Li et al. Case 1 step 1): the camera's pose in the scan-head frame from the
    head's axis lines drawn on the board on the plate: rotation and centre error against the
    true pose, and what the whole calibration's error is on the plate z = 0 (a grid over the
    field, where the calibrated camera puts the pixels the true camera sees it at).
(c) Recalibration after a camera move (Wang et al. 2018 §2.3): the true camera is turned by
    --move-deg and moved by --move-mm; spots are recorded on the plate at --heights; the pose
    is re-estimated (intrinsics: the operator's) with the nominal head beams, with a field
    correction fitted beforehand (--field-grid² spots, camera not yet moved), and with the true
    beams (a reference: what spot noise and the intrinsics leave). Before/after errors on the
    plate as in (b), and the point-to-beam RMS the fit reports.

Run: .venv/bin/python benchmarks/camera_calibration.py [--seed N] [--binning 1|2]
     [--views 15] [--grid 7] [--field-grid 11] [--keep DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table

from insitu.calibrate.camera import INTRINSIC_NAMES
from insitu.calibrate.field_file import save_field_correction
from insitu.calibrate.pose_from_spots import pose_from_spots
from insitu.formats.calibration import CameraCalibration
from insitu.formats.sequence import Sequence
from insitu.geometry.beams import axis_lines
from insitu.geometry.camera import CameraModel
from insitu.services.camera import (
    calibrate_camera,
    pose_change,
    recalibrate_camera_pose,
    spot_observations,
)
from insitu.services.common import camera_model
from insitu.services.field import calibrate_field
from insitu.services.record import record_camera_calibration, record_field_calibration
from insitu.services.station import simulated
from insitu.sim.board import BoardViews
from insitu.sim.rig import default_rig, move_camera
from insitu.sim.world import SimWorld

console = Console(width=150)


def timed(f, *args, **kw):
    t0 = time.perf_counter()
    out = f(*args, **kw)
    return out, time.perf_counter() - t0


def image_error_px(true: CameraModel, est: CameraModel, dist_only: bool = False
                   ) -> tuple[float, float]:
    """RMS and max, px, over a grid on the image, between where the true camera and ``est``
    put the same viewing directions (``dist_only``: ``est``'s distortion with the true K)."""
    u, v = np.meshgrid(np.linspace(0, true.width - 1, 41), np.linspace(0, true.height - 1, 35))
    uv = np.column_stack([u.ravel(), v.ravel()])
    xy = true.normalize(uv)
    K = true.K if dist_only else est.K
    rays = np.column_stack([xy, np.ones(len(xy))])
    got = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, est.dist)[0].reshape(-1, 2)
    e = np.linalg.norm(got - uv, axis=1)
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def plate_error_mm(true: CameraModel, est: CameraModel, half: float = 90.0
                   ) -> tuple[float, float]:
    """RMS and max distance, mm, on z = 0 between grid points (±half, those the true camera
    sees) and where ``est`` intersects the plate with the pixels the true camera sees them at."""
    g = np.linspace(-half, half, 19)
    X = np.array([(x, y, 0.0) for y in g for x in g])
    uv = true.project(X)
    keep = true.in_image(np.nan_to_num(uv, nan=-1e9))
    o, d = est.rays(uv[keep])
    on_plate = o[:2] + (-o[2] / d[:, 2])[:, None] * d[:, :2]
    e = np.linalg.norm(on_plate - X[keep, :2], axis=1)
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def intrinsics_table(true: CameraModel, cal: CameraCalibration, t_rec: float, t_cal: float
                     ) -> Table:
    est = np.r_[np.array(cal.camera.K)[[0, 1, 0, 1], [0, 1, 2, 2]], cal.camera.dist]
    ref = np.r_[true.K[[0, 1, 0, 1], [0, 1, 2, 2]], true.dist]
    std = dict(zip(cal.std_intrinsics_order or INTRINSIC_NAMES, cal.std_intrinsics))
    r = cal.residuals
    t = Table(title=f"(a) intrinsics from {int(r['views_used'])} views: reprojection RMS "
                    f"{cal.rms_px:.4f} px (worst view {r['max_view_rms_px']:.4f}); recording "
                    f"{t_rec:.1f} s, calibration {t_cal:.1f} s")
    for c in ("", "true", "estimated", "error", "error %", "1σ", "|error| / 1σ"):
        t.add_column(c, justify="right" if c else "left")
    for name, a, b in zip(INTRINSIC_NAMES, ref, est):
        s = std.get(name, np.nan)
        pct = f"{100 * (b - a) / a:+.4f}" if name in ("fx", "fy") else ""
        fmt = ".3f" if name in ("fx", "fy", "cx", "cy") else ".5f"
        t.add_row(name, f"{a:{fmt}}", f"{b:{fmt}}", f"{b - a:+{fmt}}", pct, f"{s:{fmt}}",
                  f"{abs(b - a) / s:.1f}")
    est_cam = camera_model(cal.camera)
    for label, dist_only in (("distortion over the image, px", True),
                             ("all intrinsics over the image, px", False)):
        rms, mx = image_error_px(true, est_cam, dist_only)
        t.add_row(label, "", f"RMS {rms:.4f}", f"max {mx:.4f}", "", "", "")
    return t


def pose_columns(table: Table) -> Table:
    for c in ("", "rot err °", "centre err mm", "plate RMS mm", "plate max mm"):
        table.add_column(c, justify="right" if c else "left")
    return table


def pose_row(name: str, true: CameraModel, est: CameraModel, *extra: str) -> list[str]:
    deg, mm = pose_change(true, est)
    rms, mx = plate_error_mm(true, est)
    return [name, f"{deg:.4f}", f"{mm:.3f}", f"{rms:.4f}", f"{mx:.4f}", *extra]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--binning", type=int, default=1, choices=(1, 2),
                    help="2: quarter-size frames (the alignment needs at least that)")
    ap.add_argument("--views", type=int, default=15, help="checkerboard views")
    ap.add_argument("--grid", type=int, default=7, help="recalibration spots per side")
    ap.add_argument("--heights", type=str, default="0,20", help="recalibration plate heights, mm")
    ap.add_argument("--field-grid", type=int, default=11, help="field calibration spots per side")
    ap.add_argument("--move-deg", type=float, default=0.5)
    ap.add_argument("--move-mm", type=float, default=2.0)
    ap.add_argument("--keep", type=Path, default=None, help="keep the recordings here")
    args = ap.parse_args()

    rig = default_rig(args.seed, binning=args.binning)
    true = rig.camera
    tmp = Path(args.keep or tempfile.mkdtemp(prefix="camera-bench-"))
    tmp.mkdir(parents=True, exist_ok=True)
    console.print(f"rig seed {args.seed}, {true.width}×{true.height} px (binning {args.binning})"
                  f" → {tmp}")

    # (a) intrinsics and (b) alignment, from one recording
    world = SimWorld(rig, seed=args.seed)
    board = BoardViews(world, args.views, lines=axis_lines())
    _, t_rec = timed(record_camera_calibration, simulated(world), tmp / "camera-cal", board,
                     args.views, axis_lines=axis_lines(), truth=board.truth)
    cal, t_cal = timed(calibrate_camera, tmp / "camera-cal")
    console.print(intrinsics_table(true, cal, t_rec, t_cal))
    K = np.array(cal.camera.K)
    focal = 100 * max(abs(K[0, 0] / true.K[0, 0] - 1), abs(K[1, 1] / true.K[1, 1] - 1))
    console.print(f"focal length error {focal:.4f} % (target ≤ 0.1 %: "
                  f"{'met' if focal <= 0.1 else 'NOT met'})\n", highlight=False)
    est = camera_model(cal.camera)
    r = cal.residuals
    b = pose_columns(Table(title=f"(b) camera pose in the scan-head frame from the axis lines "
                                 f"(lines at {r['alignment_angle_deg']:.3f}°, centres "
                                 f"{r['alignment_line_rms_mm']:.4f} mm RMS about them); plate "
                                 "error over ±90 mm on z = 0"))
    b.add_row(*pose_row("this calibration (intrinsics + alignment)", true, est))
    b.add_row(*pose_row("the simulated operator's calibration (reference)", true,
                        rig.operator.camera))
    console.print(b)

    # (c) recalibration after a move
    heights = [float(z) for z in args.heights.split(",")]
    _, t_field_rec = timed(record_field_calibration, simulated(SimWorld(rig, seed=args.seed)),
                           tmp / "field-cal", n=args.field_grid)
    field, t_field = timed(calibrate_field, tmp / "field-cal")
    save_field_correction(tmp / "field.json", field)
    moved = move_camera(rig, args.move_deg, args.move_mm, args.seed)
    _, t_spots = timed(record_field_calibration, simulated(SimWorld(moved, seed=args.seed + 1)),
                       tmp / "spots", n=args.grid, heights=heights)
    c = Table(title=f"(c) recalibration after the camera turned {args.move_deg:g}° and moved "
                    f"{args.move_mm:g} mm: {args.grid}×{args.grid} spots at "
                    f"{', '.join(f'{z:g}' for z in heights)} mm (recorded in {t_spots:.1f} s); "
                    f"field correction from {args.field_grid}×{args.field_grid} spots "
                    f"(recorded {t_field_rec:.1f} s, fitted {t_field:.1f} s, CV RMS "
                    f"{field.residuals['cv_rms_mm']:.3f} mm)")
    pose_columns(c)
    for col in ("pt-beam RMS mm", "1σ rot °", "1σ t mm", "time s"):
        c.add_column(col, justify="right")
    blank = ("", "", "", "")
    c.add_row(*pose_row("before the move (operator's)", true, rig.operator.camera), *blank)
    c.add_row(*pose_row("after the move, old pose", moved.camera, rig.operator.camera), *blank)
    for name, field_file in (("recalibrated, nominal beams", None),
                             ("recalibrated, field-corrected", tmp / "field.json")):
        new, dt = timed(recalibrate_camera_pose, tmp / "spots", field=field_file)
        c.add_row(*pose_row(name, moved.camera, camera_model(new.camera)),
                  f"{new.residuals['point_to_beam_rms_mm']:.4f}",
                  f"{new.residuals['pose_std_rotation_deg']:.4f}",
                  f"{new.residuals['pose_std_translation_mm']:.3f}", f"{dt:.1f}")
    seq = Sequence.open(tmp / "spots")
    obs, _ = spot_observations(seq)
    op = camera_model(seq.camera)
    res = pose_from_spots(obs, op, moved.beams)
    c.add_row(*pose_row("recalibrated, true beams (ref.)", moved.camera,
                        op.with_pose(res.R, res.t)), f"{res.rms_mm:.4f}",
              f"{np.linalg.norm(res.std_rot_deg):.4f}", f"{np.linalg.norm(res.std_t_mm):.3f}", "")
    console.print(c)


if __name__ == "__main__":
    main()
