"""Simulated frames for the camera ↔ scan-head alignment (Li et al. Case 1 step 1).

The checkerboard lies flat on the calibration plate (its top at ``plate_z``, normally the focal
plane z = 0) at a random place and rotation near the field centre; the true scan head draws its
axis lines on it. A frame is the checkerboard seen by the true camera
(:func:`insitu.sim.checkerboard.render_checkerboard`, board pose from the true camera) plus the
laser signal of the physical renderer (``Renderer(ideal=False)``: true beams with the field
distortion, speckle, blur, noise) on the plate, scaled by the board's reflectance (the line is
bright on the white squares, faint on the black ones) and clipped to 8 bits.

Recording (:func:`record_camera_calibration_with_alignment`): a camera-calibration sequence
whose first frames are the usual checkerboard views (frames with only ``file``), followed by
the alignment frames, which carry ``plate_z_mm``:

* a laser-off frame of the board on the plate (``plate_z_mm`` only) — also a calibration view;
* one frame per line, with ``line`` {start, end}: the x axis (−L, 0) → (L, 0), the y axis
  (0, −L) → (0, L), and the +x half-axis (0, 0) → (L, 0) that tells +x from −x.

``truth.json`` adds ``alignment``: the board's pose in the world (``R_world_board``,
``t_world_board``: board → world) and the lines drawn.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from insitu.devices.sim import SimWorld
from insitu.formats.sequence import SequenceWriter
from insitu.geometry.camera import rotation_about
from insitu.sim.checkerboard import random_board_poses, render_checkerboard
from insitu.sim.rig import SimRig

Progress = Callable[[int, int], None]
AXIS_HALF_MM = 30.0


def axis_lines(half_mm: float = AXIS_HALF_MM) -> list[tuple[np.ndarray, np.ndarray]]:
    """The lines drawn for the alignment: x axis, y axis, +x half-axis (start, end), mm."""
    L = float(half_mm)
    return [(np.array([-L, 0.0]), np.array([L, 0.0])),
            (np.array([0.0, -L]), np.array([0.0, L])),
            (np.array([0.0, 0.0]), np.array([L, 0.0]))]


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

    def line_frame(self, start, end) -> np.ndarray:
        """(H, W) uint8: the board with the line commanded from ``start`` to ``end`` (mm)."""
        board = self.board_frame().astype(np.float32)
        laser = self.world.renderer().line_frame(start, end).astype(np.float32) - self._ambient
        white = max(float(np.percentile(board, 99.0)), 1.0)
        reflect = np.clip(cv2.GaussianBlur(board, (0, 0), 1.0) / white, 0.04, 1.0)
        return np.clip(board + reflect * laser + 0.5, 0, 255).astype(np.uint8)


def record_camera_calibration_with_alignment(
        world: SimWorld, out: Path, views: int = 15, cols: int = 9, rows: int = 6,
        square_mm: float = 10.0, half_mm: float = AXIS_HALF_MM, plate_z: float = 0.0,
        reference: bool = True, progress: Progress | None = None) -> Path:
    """A camera-calibration sequence (the views of ``record_camera_calibration``, same seed)
    followed by the alignment frames (module docstring). ``reference=False`` leaves out the
    laser-off frame (the line is then found as a ridge)."""
    rig = world.rig
    rng = np.random.default_rng(world.seed + 7)
    poses = random_board_poses(rig.camera, cols, rows, square_mm, views, rng)
    R_wb, t_wb = board_on_plate(cols, rows, square_mm, np.random.default_rng(world.seed + 11),
                                plate_z)
    lines = axis_lines(half_mm)
    truth = {"rig": rig.truth_dict(), "workpieces": [],
             "board_poses": [{"R": R.tolist(), "t": t.tolist()} for R, t in poses],
             "alignment": {"R_world_board": R_wb.tolist(), "t_world_board": t_wb.tolist(),
                           "plate_z_mm": plate_z,
                           "lines": [{"start": a.tolist(), "end": b.tolist()} for a, b in lines]}}
    board = {"cols": cols, "rows": rows, "square_mm": square_mm}
    total = views + len(lines) + int(reference)
    with SequenceWriter(out, "camera-calibration", rig.nominal.to_dict(), checkerboard=board,
                        truth=truth) as w:
        for i, (R, t) in enumerate(poses):
            w.add(render_checkerboard(rig.camera, R, t, cols, rows, square_mm, rng))
            if progress:
                progress(i + 1, total)
        scene = AlignmentScene(rig, cols, rows, square_mm, R_wb, t_wb, plate_z, world.seed)
        if reference:
            w.add(scene.board_frame(), plate_z_mm=plate_z)
        for a, b in lines:
            w.add(scene.line_frame(a, b), line={"start": a.tolist(), "end": b.tolist()},
                  plate_z_mm=plate_z)
            if progress:
                progress(len(w), total)
    return out

