"""The calibration board in the simulated world: checkerboard views at random poses in front of
the true camera, then the board flat on the plate for the camera ↔ scan-head alignment (Li et
al. Case 1 step 1). :class:`BoardViews` places it (``SimWorld.board``) view by view for
:func:`insitu.services.record.record_camera_calibration`; the simulated camera then sees it.

The checkerboard lies flat on the calibration plate (its top at ``plate_z``, normally the focal
plane z = 0) at a random place and rotation near the field centre; the true scan head draws its
axis lines on it. A frame is the checkerboard seen by the true camera
(:func:`insitu.sim.checkerboard.render_checkerboard`, board pose from the true camera) plus the
laser signal of the physical renderer (``Renderer(ideal=False)``: true beams with the field
distortion, speckle, blur, noise) on the plate, scaled by the board's reflectance (the line is
bright on the white squares, faint on the black ones) and clipped to 8 bits.

Recorded, a camera-calibration sequence's first frames are the checkerboard views (frames with
only ``file``), followed by the alignment frames, which carry ``plate_z_mm``:

* a laser-off frame of the board on the plate (``plate_z_mm`` only) — also a calibration view;
* one frame per line, with ``line`` {start, end}: the x axis (−L, 0) → (L, 0), the y axis
  (0, −L) → (0, L), and the +x half-axis (0, 0) → (L, 0) that tells +x from −x.

``truth.json`` adds ``alignment``: the board's pose in the world (``R_world_board``,
``t_world_board``: board → world) and the lines drawn.
"""

from __future__ import annotations

import cv2
import numpy as np

from insitu.geometry.camera import rotation_about
from insitu.sim.checkerboard import random_board_poses, render_checkerboard
from insitu.sim.rig import SimRig
from insitu.sim.world import LaserState, SimWorld


def board_on_plate(cols: int, rows: int, square_mm: float, rng: np.random.Generator,
                   plate_z: float = 0.0, max_offset_mm: float = 5.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """A board pose lying on the plate: (R, t) board → world, board z = world z (face up),
    any rotation about z, the field centre within ``max_offset_mm`` of the board's centre."""
    R = rotation_about([0.0, 0.0, 1.0], rng.uniform(-np.pi, np.pi))
    centre = np.array([(cols - 1) * square_mm / 2, (rows - 1) * square_mm / 2, 0.0])
    centre[:2] += rng.uniform(-max_offset_mm, max_offset_mm, 2)
    return R, -R @ centre + np.array([0.0, 0.0, plate_z])


class AlignmentScene:
    """Renders the board lying on the plate, with or without a laser line, as the true camera
    sees it. ``R_wb``, ``t_wb``: board → world."""

    def __init__(self, rig: SimRig, cols: int, rows: int, square_mm: float, R_wb: np.ndarray,
                 t_wb: np.ndarray, plate_z: float = 0.0, seed: int = 0):
        self.rig, self.board = rig, (cols, rows, square_mm)
        cam = rig.camera
        self.R_cb, self.t_cb = cam.R @ R_wb, cam.R @ t_wb + cam.t
        self.world = SimWorld(rig, plate_z=plate_z, seed=seed)
        self.rng = np.random.default_rng(seed + 101)
        ambient = self.world.renderer().ambient_frame().astype(np.float32)
        self._ambient = cv2.GaussianBlur(ambient, (0, 0), 3.0)

    def board_frame(self) -> np.ndarray:
        """(H, W) uint8: the board on the plate, laser off."""
        return render_checkerboard(self.rig.camera, self.R_cb, self.t_cb, *self.board, self.rng)

    def frame(self, laser: LaserState) -> np.ndarray:
        """What the camera sees with the laser in state ``laser`` (off or a line)."""
        return self.board_frame() if laser.kind == "off" else self.line_frame(laser.start,
                                                                              laser.end)

    def line_frame(self, start, end) -> np.ndarray:
        """(H, W) uint8: the board with the line commanded from ``start`` to ``end`` (mm)."""
        board = self.board_frame().astype(np.float32)
        laser = self.world.renderer().line_frame(start, end).astype(np.float32) - self._ambient
        white = max(float(np.percentile(board, 99.0)), 1.0)
        reflect = np.clip(cv2.GaussianBlur(board, (0, 0), 1.0) / white, 0.04, 1.0)
        return np.clip(board + reflect * laser + 0.5, 0, 255).astype(np.uint8)


class _HeldBoard:
    """The board held at (R, t) board → camera, laser off."""

    def __init__(self, camera, R, t, board, rng):
        self.camera, self.R, self.t, self.board, self.rng = camera, R, t, board, rng

    def frame(self, laser: LaserState) -> np.ndarray:
        return render_checkerboard(self.camera, self.R, self.t, *self.board, self.rng)


class BoardViews:
    """The simulated operator presenting the board: ``views`` random poses (drawn from the
    world's seed) in front of the true camera, then (view number ``views``) the board flat on
    the plate at ``plate_z``. Call it with the view number (None takes the board away);
    :attr:`truth` holds the poses."""

    def __init__(self, world: SimWorld, views: int, cols: int = 9, rows: int = 6,
                 square_mm: float = 10.0, plate_z: float = 0.0,
                 lines: list[tuple[np.ndarray, np.ndarray]] | None = None):
        self.world, self.views, self.board = world, views, (cols, rows, square_mm)
        self.rng = np.random.default_rng(world.seed + 7)
        self.poses = random_board_poses(world.rig.camera, cols, rows, square_mm, views, self.rng)
        self.plate_z = plate_z
        self.truth = {"board_poses": [{"R": R.tolist(), "t": t.tolist()} for R, t in self.poses]}
        if lines is not None:
            self.R_wb, self.t_wb = board_on_plate(cols, rows, square_mm,
                                                  np.random.default_rng(world.seed + 11), plate_z)
            self.truth["alignment"] = {
                "R_world_board": self.R_wb.tolist(), "t_world_board": self.t_wb.tolist(),
                "plate_z_mm": plate_z,
                "lines": [{"start": a.tolist(), "end": b.tolist()} for a, b in lines]}

    def __call__(self, i: int | None) -> None:
        w = self.world
        if i is None:
            w.board = None
        elif i < self.views:
            R, t = self.poses[i]
            w.board = _HeldBoard(w.rig.camera, R, t, self.board, self.rng)
        else:
            w.board = AlignmentScene(w.rig, *self.board, self.R_wb, self.t_wb, self.plate_z,
                                     w.seed)
