"""Public sets of real laser-line photographs with a known geometry, for benchmarks/real_lines.py.

None of them carries a licence, so none is in this repository: clone each repository at the
commit named below into one folder, as ``DATA/<owner>+<name>`` (git clone
https://github.com/<owner>/<name> DATA/<owner>+<name>; git -C … checkout <commit>), and give
DATA to the benchmark. Each set says where its photographs, camera and board are:

* ``desktop`` — srv/desktop_3d_scanner: 121 colour JPEGs 640 × 480 of a green line on a
  hand-held checkerboard (8 × 6 inner corners, 40 mm) in front of a room; the laser is fixed to
  the camera. Camera: ``python/calibration4.yaml``. Board pose: found in the photograph.
  The defaults of ``insitu centres`` were chosen on this set.
* ``stripe`` — hjamal3/Light-Stripe-Calibration: 6 colour JPEGs 640 × 480 of a green line
  down a paper checkerboard (6 × 8 inner corners, 40 mm) held by hand in a workshop. Camera:
  ``calibrate.py``'s ``mtx`` and ``dist``. Board pose: found in the photograph.
* ``ouc`` — OUC-Underwater-3D/Laser3D, ``激光三角法/0data/170628-air``: 14 colour BMPs
  648 × 486 (``bc1`` … ``bc14``) of a green line across a checkerboard in a dark room, the
  board's aluminium frame beside it. Camera and each photograph's board pose: the
  repository's Bouguet calibration ``calibration/Calib_Results.mat`` (5 × 4 squares of
  33.8 mm clicked in each). Light plane: through the 8 points the authors clicked on the
  stripe in photographs 1–8 (``calibration/cal_plane3.m``), cast onto those boards.
* ``circles`` — zhaocongyang/structured_LineLight_calib: 12 pairs of full-HD colour JPEGs,
  ``light_picture/light<i>.jpg`` (a red line across a board of 7 × 7 dots 37.5 mm apart,
  standing on a glossy floor beside a steel cabinet) and ``calib_picture/calib<i>.jpg`` (the
  same, laser off). Camera and the fitted light plane: ``Parameters.xml``. Board pose: the dots
  found in the laser-off photograph.

Not a set: SONG-KUN/A-novel-approach-for-Camera-and-Laser-line-calibration (commit 6a88671)
has full-HD images of a board and a blue line with a fitted plane, but they are renders of a
simulated scene, not photographs.

A board's ``area`` (board mm, x0, x1, y0, y1) is where a point is surely on its white face: the
printed pattern and as much of its white border as every photograph shows (the dots' board:
inside its black frame; the Bouguet set: the squares clicked).
"""

from __future__ import annotations

import glob
import os
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class PhotoSet:
    """One set: ``files(root)`` → the photographs; ``pose(path, bgr)`` → (R (3, 3), t (3,)
    mm) board → camera or None; ``background(path)``: its laser-off photograph or None;
    ``plane()``: the published light plane (unit normal (3,), offset mm: n·x = d) or None
    (after ``files``)."""

    name: str
    repo: str
    commit: str
    laser: str                                   # "r", "g" or "b": the laser's colour
    K: np.ndarray
    dist: np.ndarray
    area: tuple[float, float, float, float]
    files: Callable[[str], list[str]]
    pose: Callable[[str, np.ndarray], tuple[np.ndarray, np.ndarray] | None]
    background: Callable[[str], str | None] = lambda path: None
    plane: Callable[[], tuple[np.ndarray, float] | None] = lambda: None


def _checkerboard(K, dist, pattern, square, swap=False):
    """Pose finder of a checkerboard of ``pattern`` inner corners (cols, rows), ``square`` mm."""
    obj = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2) * square

    def pose(path, bgr):
        gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
        ok, corners = cv2.findChessboardCorners(gray, pattern, None)
        if not ok:
            return None
        corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3))
        _, rvec, tvec = cv2.solvePnP(obj, corners, K, dist)
        return cv2.Rodrigues(rvec)[0], tvec.ravel()
    return pose


def _folder(repo, sub, pattern):
    return lambda root: sorted(glob.glob(os.path.join(root, repo.replace("/", "+"), sub,
                                                      pattern)))


# ---------------------------------------------------------------- srv/desktop_3d_scanner
_D_K = np.array([[620.2678375549896, 0.0, 322.94579652113293],
                 [0.0, 618.61305587237, 239.42135627438046], [0.0, 0.0, 1.0]])
_D_DIST = np.array([0.11369913583372294, -0.193716412669678, -0.0011143493279290875,
                    -0.0021599136353324592, -0.03519351082447173])
DESKTOP = PhotoSet(
    "desktop", "srv/desktop_3d_scanner", "d7c7b7eca85b3932cb9da7b70983bd3a8bfe580b", "g",
    _D_K, _D_DIST, (-80.0, 360.0, -80.0, 280.0),
    _folder("srv/desktop_3d_scanner", "python/calib_images/Laser/Calibracio17_07", "*.jpg"),
    _checkerboard(_D_K, _D_DIST, (8, 6), 40.0))

# ---------------------------------------------- hjamal3/Light-Stripe-Calibration
_S_K = np.array([[514.41205, 0.0, 329.83671], [0.0, 685.92876, 237.71471], [0.0, 0.0, 1.0]])
_S_DIST = np.array([-0.350373, 0.158447, 0.000735, -0.000231, 0.0])
STRIPE = PhotoSet(
    "stripe", "hjamal3/Light-Stripe-Calibration", "64ce9a67b32ad91e1f22ece0712a617656685b81",
    "g", _S_K, _S_DIST, (-40.0, 240.0, -40.0, 320.0),
    _folder("hjamal3/Light-Stripe-Calibration", "images", "*.jpg"),
    _checkerboard(_S_K, _S_DIST, (6, 8), 40.0))


# ---------------------------------------------------------------- OUC-Underwater-3D/Laser3D
_OUC = os.path.join("激光三角法", "0data", "170628-air")


def _ouc_calibration(root):
    from scipy.io import loadmat
    return loadmat(os.path.join(root, "OUC-Underwater-3D+Laser3D", _OUC, "calibration",
                                "Calib_Results.mat"))


class _Ouc:
    """The Bouguet calibration's camera and poses (its board frame in metres → mm)."""

    def __init__(self):
        self.cal = None

    def load(self, root):
        self.cal = _ouc_calibration(root)
        return sorted(glob.glob(os.path.join(root, "OUC-Underwater-3D+Laser3D", _OUC,
                                             "bc*.BMP")),
                      key=lambda p: int(os.path.basename(p)[2:-4]))

    def pose(self, path, bgr):
        i = int(os.path.basename(path)[2:-4])
        return self.cal[f"Rc_{i}"], 1000.0 * self.cal[f"Tc_{i}"].ravel()


_ouc = _Ouc()
_OUC_CLICKS = {1: (118, 279), 2: (107, 225), 3: (523, 143), 4: (444, 255), 5: (109, 272),
               6: (351, 213), 7: (351, 226), 8: (428, 222)}                # cal_plane3.m


def _ouc_plane(K, dist):
    """The plane through the authors' clicked stripe points (unit normal, offset mm)."""
    X = []
    for i, uv in _OUC_CLICKS.items():
        R, t = _ouc.pose(f"bc{i}.BMP", None)
        ray = cv2.undistortPoints(np.array([[uv]], np.float64), K, dist).ravel()
        ray = np.r_[ray, 1.0]
        X.append(ray * (R[:, 2] @ t) / (ray @ R[:, 2]))
    X = np.array(X)
    n = np.linalg.svd(X - X.mean(axis=0))[2][2]
    return n, float(n @ X.mean(axis=0))


OUC = PhotoSet(
    "ouc", "OUC-Underwater-3D/Laser3D", "62b416605ef9430a8104a9a3472f3c8b2908f50c", "g",
    np.array([[702.59357995, 0.0, 303.06241825], [0.0, 703.49340427, 227.21637754],
              [0.0, 0.0, 1.0]]),
    np.array([-0.14078253, 0.20232008, -0.00551167, -0.0004342, 0.0]),
    (0.0, 169.0, 0.0, 135.2), _ouc.load, _ouc.pose,
    plane=lambda: _ouc_plane(OUC.K, OUC.dist))

# ---------------------------------------------- zhaocongyang/structured_LineLight_calib
_C_K = np.array([[1144.4393086789801, 0.0, 916.05937324175795],
                 [0.0, 1142.4883309976474, 522.04970408082136], [0.0, 0.0, 1.0]])
_C_DIST = np.array([-2.9611559154421103e-02, -3.3507405096527815e-04, 7.8914871567435929e-03,
                    -3.9387309197063357e-04, 4.5913143563334771e-02])
_C_PLANE = np.array([-1.3051671468331907e-01, -6.3959525011364002e+00, 1.0])   # A x + B y + z
_C_D = 3.0491858062622839e+02                                                    # = D, mm


def _circles_pose(path, bgr):
    off = cv2.imread(path.replace("light_picture", "calib_picture").replace("light", "calib"))
    gray = cv2.cvtColor(off if off is not None else bgr, cv2.COLOR_BGR2GRAY)
    ok, centres = cv2.findCirclesGrid(gray, (7, 7), flags=cv2.CALIB_CB_SYMMETRIC_GRID)
    if not ok:
        return None
    obj = np.zeros((49, 3), np.float32)
    obj[:, :2] = np.mgrid[0:7, 0:7].T.reshape(-1, 2) * 37.5
    _, rvec, tvec = cv2.solvePnP(obj, centres, _C_K, _C_DIST)
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


CIRCLES = PhotoSet(
    "circles", "zhaocongyang/structured_LineLight_calib",
    "672d6417f0ee723e0596a8f0ef03bdb3372768a9", "r", _C_K, _C_DIST,
    (-28.0, 253.0, -28.0, 253.0),
    _folder("zhaocongyang/structured_LineLight_calib", "light_picture", "light*.jpg"),
    _circles_pose,
    lambda p: p.replace("light_picture", "calib_picture").replace("light", "calib"),
    lambda: (_C_PLANE / np.linalg.norm(_C_PLANE), _C_D / np.linalg.norm(_C_PLANE)))

SETS = {s.name: s for s in (DESKTOP, STRIPE, OUC, CIRCLES)}
TUNED = {"desktop": "defaults chosen on all of it",
         "circles": "the tracks shaped on all of it",
         "ouc": "first half (bc1–bc7) looked at, nothing tuned on it; second half held out",
         "stripe": "tuned on the first half (2_, 3_right); all of it seen when the channel "
                   "rule was chosen"}
"""How each set has been used: the halves are real_lines.half's of the set's photographs with
a board pose (``files``' order)."""
