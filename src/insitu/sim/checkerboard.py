"""Checkerboard frames for camera calibration, seen by the simulated (true) camera.

Every pixel's ray is intersected with the board plane; the checker pattern is box-filtered
over the pixel footprint (no aliasing), then lens blur, vignetting, ambient light and noise.
"""

from __future__ import annotations

import cv2
import numpy as np

from insitu.geometry.camera import CameraModel, rotation_about


def board_corners(cols: int, rows: int, square_mm: float) -> np.ndarray:
    """(cols·rows, 3) inner corners in the board frame (z = 0), row by row, mm — OpenCV's
    order for ``findChessboardCorners`` with patternSize (cols, rows)."""
    gx, gy = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]) * square_mm


def random_board_poses(camera: CameraModel, cols: int, rows: int, square_mm: float, n: int,
                       rng: np.random.Generator, max_tilt_deg: float = 35.0,
                       depth_mm: float | None = None, max_tries: int = 10000
                       ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` board poses (R, t: board → camera) with all corners well inside the image, at
    about ``depth_mm`` from the camera (default: the camera's distance from the world origin).
    ValueError when ``max_tries`` random poses do not give ``n``."""
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    centre = (np.array([cols - 1, rows - 1, 0]) * square_mm) / 2
    margin = 0.06 * min(camera.width, camera.height)
    depth0 = float(np.linalg.norm(camera.centre_world)) if depth_mm is None else float(depth_mm)
    if not depth0 > 0:
        raise ValueError("random_board_poses: the board needs a positive depth_mm")
    for _ in range(max_tries):
        if len(poses) == n:
            break
        tilt = rotation_about(np.append(rng.normal(size=2), 0.0), np.deg2rad(rng.uniform(5, max_tilt_deg)))
        spin = rotation_about([0, 0, 1], rng.uniform(-np.pi, np.pi))
        R = tilt @ spin
        depth = depth0 * rng.uniform(0.8, 1.1)
        xy = rng.uniform(-0.25, 0.25, 2) * depth * camera.width / camera.K[0, 0]
        t = np.array([xy[0], xy[1], depth]) - R @ centre
        pts = board_corners(cols, rows, square_mm) @ R.T + t
        ident = CameraModel(camera.width, camera.height, camera.K, camera.dist, np.eye(3), np.zeros(3))
        uv = ident.project(pts)
        if np.isfinite(uv).all() and ident.in_image(uv, margin).all():
            poses.append((R, t))
    if len(poses) < n:
        raise ValueError(f"random_board_poses: only {len(poses)} of {n} poses keep the board "
                         "in the image")
    return poses


def render_checkerboard(camera: CameraModel, R: np.ndarray, t: np.ndarray, cols: int, rows: int,
                        square_mm: float, rng: np.random.Generator) -> np.ndarray:
    """(H, W) uint8 frame of the board (pose R, t: board → camera frame) with a white border
    of one square. ``camera``'s own pose is ignored: the board pose is camera-relative."""
    H, W = camera.height, camera.width
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    ident = CameraModel(W, H, camera.K, camera.dist, np.eye(3), np.zeros(3))
    xy = ident.normalize(np.column_stack([u.ravel(), v.ravel()]))
    rays = np.column_stack([xy, np.ones(len(xy))])
    n_board = R[:, 2]
    s = (n_board @ t) / (rays @ n_board)
    pts = (s[:, None] * rays - t) @ R                                # board frame
    bx, by = pts[:, 0] / square_mm, pts[:, 1] / square_mm
    # pixel footprint in squares: rate of change of board coordinates across one pixel
    fw = np.maximum(s * np.hypot(1 / camera.K[0, 0], 1 / camera.K[1, 1])
                    / abs(n_board[2]) / square_mm, 1e-6)
    # corners at integer board coords; squares beyond the inner corners' range by one: border
    sx, sy = _filtered_square_wave(bx, fw), _filtered_square_wave(by, fw)
    checker = 0.5 + 0.5 * sx * sy
    inside = (bx > -1) & (bx < cols) & (by > -1) & (by < rows)
    board = (bx > -2) & (bx < cols + 1) & (by > -2) & (by < rows + 1) & (s > 0)
    albedo = np.where(inside, 0.05 + 0.85 * checker, np.where(board, 0.9, 0.15))
    r2 = (xy**2).sum(1)
    image = (200.0 * albedo / (1 + 0.8 * r2) ** 2).reshape(H, W).astype(np.float32)
    image = cv2.GaussianBlur(image, (0, 0), 0.7)
    image += rng.standard_normal(image.shape, dtype=np.float32) * np.sqrt(image / 8.0 + 1.5)
    return np.clip(image + 0.5, 0, 255).astype(np.uint8)


def _filtered_square_wave(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Square wave sign(sin(πx)) (period 2) box-filtered over width ``w``: in [−1, 1]."""
    def tri(a):  # integral of the square wave, period 2
        f = np.mod(a, 2.0)
        return np.where(f < 1, f, 2 - f)
    return (tri(x + w / 2) - tri(x - w / 2)) / w
