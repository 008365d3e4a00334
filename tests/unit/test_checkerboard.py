"""Simulated checkerboard frames: OpenCV finds the corners where the true camera puts them."""

import cv2
import numpy as np

from insitu.geometry.camera import CameraModel
from insitu.sim.checkerboard import board_corners, random_board_poses, render_checkerboard
from insitu.sim.rig import default_rig


def test_corners_found_where_the_true_camera_projects_them():
    rig = default_rig(seed=5, binning=2)
    cam = rig.camera
    rng = np.random.default_rng(0)
    cols, rows, square = 9, 6, 10.0
    errors = []
    for R, t in random_board_poses(cam, cols, rows, square, 4, rng):
        img = render_checkerboard(cam, R, t, cols, rows, square, rng)
        found, corners = cv2.findChessboardCorners(img, (cols, rows))
        assert found
        corners = cv2.cornerSubPix(img, corners, (5, 5), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-3))
        ident = CameraModel(cam.width, cam.height, cam.K, cam.dist, R, t)
        truth = ident.project(board_corners(cols, rows, square))
        d = corners.reshape(-1, 2) - truth
        # OpenCV may number the grid from the other end: take the better of the two orders
        d2 = corners.reshape(-1, 2)[::-1] - truth
        d = d if np.abs(d).mean() < np.abs(d2).mean() else d2
        errors.append(np.sqrt((d**2).sum(1)))
    err = np.concatenate(errors)
    assert np.sqrt(np.mean(err**2)) < 0.15, f"corner RMS {np.sqrt(np.mean(err**2)):.3f} px"
