"""Camera ↔ scan-head (world) frame from the head's axis lines drawn on a flat board
(Li et al. Case 1 step 1, done computationally).

The board lies on the plate, its top at ``plate_z`` (normally the focal plane z = 0), in an
unknown place and rotation. The head draws its x axis (y = 0) and its y axis (x = 0) on it,
one line per frame. Then:

1. board → camera pose by solvePnP on the board's corners (intrinsics from the calibration);
2. the laser line in each frame: the frame minus a laser-off frame of the same board (or, with
   none, a white top-hat that keeps narrow bright ridges), sub-pixel centres by the gray
   centroid across the line (:func:`insitu.vision.centres.line_centres`) inside the printed
   squares of the board;
3. centres back-projected onto the board plane, one 2-D line fitted per axis (total least
   squares, 3σ outliers dropped);
4. the intersection is the world origin; the y line gives world y, x is the x line made
   orthogonal to it, z = x × y points to the camera's side of the board. The angle between
   the lines is reported (and must be 90° within ``max_angle_error_deg``);
5. which way +x and +y point: a symmetric axis line cannot tell, so the frames must include a
   line that is not symmetric about the origin (e.g. the +x half-axis (0, 0) → (L, 0)); of
   the two frames consistent with 4., the one that puts every frame's points on its own
   commanded segment wins.

Errors left: a field distortion δ(x, y) of the head bends the drawn axes; near the centre only
its linear part matters, which rotates each axis by ∂δ_y/∂x (x axis) or ∂δ_x/∂y (y axis) — on
the simulated rig ≈ 0.02–0.06°, i.e. ~0.1 mm at 90 mm from the centre. Short lines (±30 mm)
keep the higher-order bending out; a field correction calibrated afterwards in this world frame
absorbs what is left.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.calibrate.camera import BoardSpec
from insitu.errors import CalibrationError
from insitu.geometry.camera import CameraModel
from insitu.vision.centres import line_centres

MIN_LINE_POINTS = 30


@dataclass(frozen=True)
class LineFrame:
    """One frame of a commanded line: ``image`` (H, W), ``start``/``end`` (2,) world mm on the
    plate, ``name`` for messages."""

    image: np.ndarray
    start: np.ndarray
    end: np.ndarray
    name: str


@dataclass(frozen=True)
class BoardLine:
    """A laser line seen on the board: centres ``points`` (N, 2) board mm, the fitted line
    (``point`` (2,), unit ``direction`` (2,)) and the RMS distance of the points to it, mm."""

    points: np.ndarray
    point: np.ndarray
    direction: np.ndarray
    rms_mm: float


@dataclass(frozen=True)
class Alignment:
    """World (scan-head) frame found on the board. ``R``, ``t``: T_cam_world (a world point X
    maps to ``R @ X + t`` in the camera). ``R_board_world``, ``t_board_world``: world → board.
    ``angle_deg``: angle between the drawn x and y lines. ``line_rms_mm``: RMS of the line
    centres about their fitted lines. ``points``: per frame name, how many centres were used."""

    R: np.ndarray
    t: np.ndarray
    R_board_world: np.ndarray
    t_board_world: np.ndarray
    angle_deg: float
    line_rms_mm: float
    points: dict[str, int]

    def summary(self) -> dict[str, float]:
        return {"alignment_angle_deg": self.angle_deg,
                "alignment_line_rms_mm": self.line_rms_mm}


# -- image → board ---------------------------------------------------------------------------
def normalize(uv: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(N, 2) distorted pixels → (N, 2) undistorted normalised coordinates (x/z, y/z)."""
    return CameraModel(1, 1, K, dist, np.eye(3), np.zeros(3)).normalize(uv)


def board_to_image(xy: np.ndarray, K, dist, R_cb, t_cb) -> np.ndarray:
    """(N, 2) board points (z = 0), mm → (N, 2) distorted pixels."""
    pts = np.column_stack([np.asarray(xy, float).reshape(-1, 2), np.zeros(len(xy))])
    uv, _ = cv2.projectPoints(pts, cv2.Rodrigues(R_cb)[0], t_cb, K, dist)
    return uv.reshape(-1, 2)


def image_to_board(uv: np.ndarray, K, dist, R_cb, t_cb) -> np.ndarray:
    """(N, 2) distorted pixels → (N, 2) points on the board plane z = 0, board frame, mm."""
    xy = normalize(uv, K, dist)
    rays = np.column_stack([xy, np.ones(len(xy))])
    n = R_cb[:, 2]
    s = (n @ t_cb) / (rays @ n)
    return ((s[:, None] * rays - t_cb) @ R_cb)[:, :2]


def laser_signal(image: np.ndarray, reference: np.ndarray | None, ridge_px: int = 15
                 ) -> np.ndarray:
    """(H, W) float32: the laser alone. With a laser-off ``reference`` of the same scene, the
    difference; without, a white top-hat of width ``ridge_px`` (keeps ridges narrower than
    that: the laser line, not the white squares)."""
    img = np.asarray(image, np.float32)
    if reference is not None:
        return img - np.asarray(reference, np.float32)
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (ridge_px | 1, ridge_px | 1))
    return cv2.morphologyEx(cv2.GaussianBlur(img, (0, 0), 0.7), cv2.MORPH_TOPHAT, k)


def _board_mask(shape, board: BoardSpec, K, dist, R_cb, t_cb, inset_mm: float) -> np.ndarray:
    x0, x1, y0, y1 = board.area_mm()
    x0, x1, y0, y1 = x0 + inset_mm, x1 - inset_mm, y0 + inset_mm, y1 - inset_mm
    s = np.linspace(0.0, 1.0, 40)
    edge = np.concatenate([np.column_stack([x0 + (x1 - x0) * s, np.full(40, y0)]),
                           np.column_stack([np.full(40, x1), y0 + (y1 - y0) * s]),
                           np.column_stack([x1 - (x1 - x0) * s, np.full(40, y1)]),
                           np.column_stack([np.full(40, x0), y1 - (y1 - y0) * s])])
    poly = board_to_image(edge, K, dist, R_cb, t_cb)
    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.round(poly).astype(np.int32)], 1)
    return mask.astype(bool)


def _fit_line(pts: np.ndarray, iterations: int = 4) -> tuple[np.ndarray, np.ndarray, float,
                                                              np.ndarray]:
    """Total-least-squares 2-D line through ``pts`` (N, 2), dropping > 3σ points: point,
    unit direction, RMS distance, inlier mask."""
    keep = np.ones(len(pts), bool)
    for _ in range(iterations):
        c = pts[keep].mean(axis=0)
        _, _, vt = np.linalg.svd(pts[keep] - c, full_matrices=False)
        d = vt[0]
        dist = np.abs((pts - c) @ np.array([-d[1], d[0]]))
        rms = float(np.sqrt(np.mean(dist[keep] ** 2)))
        new = dist <= max(3.0 * rms, 1e-9)
        if np.array_equal(new, keep) or new.sum() < 2:
            break
        keep = new
    return c, d, rms, keep


def find_board_line(frame: LineFrame, reference: np.ndarray | None, board: BoardSpec,
                    K: np.ndarray, dist: np.ndarray, R_cb: np.ndarray, t_cb: np.ndarray
                    ) -> BoardLine:
    """The laser line of ``frame`` on the board: centres in board mm and the fitted line.
    CalibrationError naming the frame if no line is found on the board."""
    img = np.asarray(frame.image)
    H, W = img.shape
    # the size of a square in pixels sets the ridge filter and the search band
    sq = np.linalg.norm(np.diff(board_to_image(np.array([[0, 0], [board.square_mm, 0]]),
                                               K, dist, R_cb, t_cb), axis=0))
    signal = laser_signal(img, reference, ridge_px=int(max(7, 0.15 * sq)))
    mask = _board_mask((H, W), board, K, dist, R_cb, t_cb, 0.1 * board.square_mm)
    if reference is None:      # the ridge filter also answers at the squares' corners
        x0, x1, y0, y1 = board.area_mm()
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1e-6, board.square_mm),
                             np.arange(y0, y1 + 1e-6, board.square_mm))
        corners = board_to_image(np.column_stack([gx.ravel(), gy.ravel()]), K, dist, R_cb, t_cb)
        blots = np.zeros((H, W), np.uint8)
        for u, v in np.round(corners).astype(int):
            cv2.circle(blots, (int(u), int(v)), int(np.ceil(0.22 * sq)), 1, -1)
        mask &= blots == 0
    signal[~mask] = 0
    vals = signal[mask]
    noise = 1.4826 * float(np.median(np.abs(vals - np.median(vals)))) if vals.size else 0.0
    peak = float(np.percentile(vals, 99.9)) if vals.size else 0.0
    thr = max(0.4 * peak, 8.0 * noise, 10.0)
    vv, uu = np.nonzero(signal > thr)
    if len(uu) < MIN_LINE_POINTS:
        raise CalibrationError(f"{frame.name}: no laser line found on the board "
                               f"({len(uu)} bright pixels; brightest {peak:.0f} DN above the board)")
    # coarse straight line through the bright pixels, in undistorted pixel coordinates
    und = normalize(np.column_stack([uu, vv]).astype(np.float64), K, dist) @ K[:2, :2].T + K[:2, 2]
    c, d, rms, keep = _fit_line(und)
    if keep.sum() < MIN_LINE_POINTS:
        raise CalibrationError(f"{frame.name}: no straight laser line found on the board")
    s = (und[keep] - c) @ d
    samples = c + np.linspace(s.min(), s.max(), 400)[:, None] * d
    xy = np.column_stack([samples, np.ones(len(samples))]) @ np.linalg.inv(K).T
    curve, _ = cv2.projectPoints(xy, np.zeros(3), np.zeros(3), K, dist)   # distorted
    curve = curve.reshape(-1, 2)
    rows = abs(d[0]) >= abs(d[1])          # runs along the rows: one centre per column
    a, b = (curve[:, 0], curve[:, 1]) if rows else (curve[:, 1], curve[:, 0])
    order = np.argsort(a)
    n = W if rows else H
    centre = np.interp(np.arange(n), a[order], b[order], left=np.nan, right=np.nan)
    half = max(4.0, 0.12 * sq)
    band = (centre - half, centre + half)
    sig = np.clip(signal, 0, None).astype(np.float32)
    cen = line_centres(sig, "gray", "rows" if rows else "cols", band=band, k=0.3,
                       min_peak=thr, min_contrast=thr / 2, window=int(np.ceil(half)))
    uv = cen.uv
    if len(uv):
        inside = mask[np.clip(np.round(uv[:, 1]).astype(int), 0, H - 1),
                      np.clip(np.round(uv[:, 0]).astype(int), 0, W - 1)]
        uv = uv[inside]
    if len(uv) < MIN_LINE_POINTS:
        raise CalibrationError(f"{frame.name}: laser line too short on the board "
                               f"({len(uv)} centres, need {MIN_LINE_POINTS})")
    pts = image_to_board(uv, K, dist, R_cb, t_cb)
    p, direction, rms, keep = _fit_line(pts)
    return BoardLine(pts[keep], p, direction, rms)


# -- board → world --------------------------------------------------------------------------
def _axis_of(frame: LineFrame, tol: float = 1e-6) -> str | None:
    (x0, y0), (x1, y1) = frame.start, frame.end
    if abs(y0) < tol and abs(y1) < tol:
        return "x"
    if abs(x0) < tol and abs(x1) < tol:
        return "y"
    return None


def _combined_line(lines: list[BoardLine]) -> tuple[np.ndarray, np.ndarray, float]:
    pts = np.concatenate([ln.points for ln in lines])
    c, d, rms, _ = _fit_line(pts)
    return c, d, rms


def _on_segment(world_xy: np.ndarray, frame: LineFrame) -> float:
    """Fraction of ``world_xy`` (N, 2) lying on the frame's commanded segment (± tolerance)."""
    a, b = np.asarray(frame.start, float), np.asarray(frame.end, float)
    length = float(np.linalg.norm(b - a))
    u = (b - a) / length
    s = (world_xy - a) @ u
    off = np.abs((world_xy - a) @ np.array([-u[1], u[0]]))
    tol = max(2.0, 0.1 * length)
    return float(np.mean((s > -tol) & (s < length + tol) & (off < tol)))


def align_to_head(frames: list[LineFrame], reference: np.ndarray | None, board: BoardSpec,
                  K: np.ndarray, dist: np.ndarray, R_cb: np.ndarray, t_cb: np.ndarray,
                  plate_z: float = 0.0, max_angle_error_deg: float = 1.0) -> Alignment:
    """T_cam_world from the axis lines drawn on the board (module docstring).

    frames: the line frames (world lines along y = 0 fit the x axis, along x = 0 the y axis,
    any other line only helps to tell + from −). reference: laser-off frame of the same board,
    or None. R_cb, t_cb: board → camera. plate_z: height of the board's top, world mm.
    """
    lines = {f.name: find_board_line(f, reference, board, K, dist, R_cb, t_cb) for f in frames}
    groups = {ax: [lines[f.name] for f in frames if _axis_of(f) == ax] for ax in "xy"}
    for ax, other in (("x", "y = 0"), ("y", "x = 0")):
        if not groups[ax]:
            raise CalibrationError(f"alignment frames: no {ax}-axis line (a frame whose line "
                                   f"runs along {other})")
    px, dx, rms_x = _combined_line(groups["x"])
    py, dy, rms_y = _combined_line(groups["y"])
    cosang = abs(float(dx @ dy))
    angle = float(np.degrees(np.arccos(np.clip(cosang, -1, 1))))
    if abs(angle - 90.0) > max_angle_error_deg:
        raise CalibrationError(f"alignment frames: the x and y axis lines meet at {angle:.2f}°, "
                               f"expected 90° ± {max_angle_error_deg:g}°")
    # intersection: px + a dx = py + b dy
    a, _ = np.linalg.solve(np.column_stack([dx, -dy]), py - px)
    origin = px + a * dx
    # world z: toward the camera's side of the board
    cam_b = -R_cb.T @ t_cb
    z_b = np.array([0.0, 0.0, 1.0 if cam_b[2] > 0 else -1.0])
    best = []
    for sign in (1.0, -1.0):
        y_b = np.append(sign * dy, 0.0)
        x_b = np.append(dx - (dx @ dy) * dy, 0.0)
        x_b /= np.linalg.norm(x_b)
        if np.cross(x_b, y_b) @ z_b < 0:
            x_b = -x_b
        R_bw = np.column_stack([x_b, y_b, z_b])
        o_b = np.append(origin, 0.0) - plate_z * z_b
        score = min([_on_segment(((np.column_stack([lines[f.name].points,
                                                        np.zeros(len(lines[f.name].points))])
                                       - o_b) @ R_bw)[:, :2], f) for f in frames])
        best.append((score, R_bw, o_b))
    (s1, R_bw, o_b), (s2, *_) = sorted(best, key=lambda b: -b[0])
    if s1 - s2 < 0.5:
        raise CalibrationError("alignment frames: cannot tell +x from −x — every line is "
                               "symmetric about the origin; add a line that is not (e.g. the "
                               "+x half-axis from (0, 0) to (L, 0))")
    if s1 < 0.8:
        raise CalibrationError(f"alignment frames: the lines seen do not lie where they were "
                               f"commanded (only {100 * s1:.0f}% of one frame's centres on its segment)")
    R = R_cb @ R_bw
    t = R_cb @ o_b + t_cb
    n = {k: len(v.points) for k, v in lines.items()}
    rms = float(np.sqrt((rms_x**2 * sum(len(g.points) for g in groups["x"])
                         + rms_y**2 * sum(len(g.points) for g in groups["y"]))
                        / sum(len(g.points) for ax in "xy" for g in groups[ax])))
    return Alignment(R, t, R_bw, o_b, angle, rms, n)
