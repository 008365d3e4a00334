"""Camera intrinsics from views of a checkerboard (or a ChArUco board).

Detection: both OpenCV chessboard detectors on a copy reduced to ≤ 1400 px wide — the sector-based
``findChessboardCornersSB`` (exhaustive, normalised) and the classic ``findChessboardCorners``
(adaptive threshold, normalised) — each refined by ``cornerSubPix`` on the full frame with a window
of ~0.2 × the smallest corner spacing of the view, clear of the board's edge beyond its outer
corners (a fixed 23 × 23 px window, OpenCV's tutorial's, reaches it on foreshortened views: on
OpenCV's ``left*.jpg`` it moves those corners by up to 6 px and doubles the RMS; OpenCV's own
``samples/python/calibrate.py`` uses 11 × 11); of two results the one whose grid is smoother (cubic
fit of pixel over grid index) is kept, numbered as SB numbers it. On OpenCV's 13 ``left*.jpg``
photos SB alone finds 11 (exhaustive 13), classic 13; refined, both give the same corners. ChArUco
boards through ``cv2.aruco.CharucoDetector`` (partial views allowed). Calibration:
``cv2.calibrateCameraExtended`` with OpenCV's 5-term distortion ``[k1, k2, p1, p2, k3]``; views
whose RMS reprojection error is > ``outlier_factor`` × the median are dropped and the camera
recalibrated, until none is. The parameter uncertainties are OpenCV's ``stdDeviationsIntrinsics`` (σ
from the final residuals, Gauss–Newton covariance).

Board frame: z = 0 on the board. Chessboard: origin at the first inner corner, x along
``cols`` (OpenCV's corner order). ChArUco: OpenCV's board frame (origin at the outer corner).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from insitu.errors import CalibrationError

MIN_VIEWS = 4
_SUBPIX = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
_DETECT_MAX_WIDTH = 1400
INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


@dataclass(frozen=True)
class BoardSpec:
    """``cols`` × ``rows`` inner corners (OpenCV's patternSize), square side ``square_mm``.
    ``charuco``: None for a plain chessboard, else ``{"dictionary": "DICT_4X4_50",
    "marker_mm": 7.0}`` (the sequence's optional ``checkerboard.charuco``)."""

    cols: int
    rows: int
    square_mm: float
    charuco: dict | None = None

    @classmethod
    def from_spec(cls, spec) -> "BoardSpec":
        """From a ``CheckerboardSpec`` (docs/formats.md) or a dict, reading the optional
        ``charuco``."""
        d = spec if isinstance(spec, dict) else {**spec.model_dump(), **(spec.model_extra or {})}
        charuco = d.get("charuco")
        if charuco is not None:
            if not hasattr(cv2, "aruco"):
                raise CalibrationError("checkerboard.charuco: this OpenCV has no aruco module "
                                       "(install opencv-contrib or use a plain chessboard)")
            if not isinstance(charuco, dict):
                raise CalibrationError(f"checkerboard.charuco: expected an object with "
                                       f"'dictionary' and 'marker_mm', got {charuco!r}")
            name = str(charuco.get("dictionary", "DICT_4X4_50"))
            if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
                raise CalibrationError(f"checkerboard.charuco.dictionary: unknown ArUco "
                                       f"dictionary {name!r} (e.g. 'DICT_4X4_50')")
            marker = float(charuco.get("marker_mm", 0.7 * float(d["square_mm"])))
            if not 0 < marker < float(d["square_mm"]):
                raise CalibrationError(f"checkerboard.charuco.marker_mm: expected 0 < marker_mm "
                                       f"< square_mm = {d['square_mm']}, got {marker}")
            charuco = {"dictionary": name, "marker_mm": marker}
        return cls(int(d["cols"]), int(d["rows"]), float(d["square_mm"]), charuco)

    def describe(self) -> str:
        kind = f"ChArUco ({self.charuco['dictionary']})" if self.charuco else "chessboard"
        return f"{kind} of {self.cols}×{self.rows} inner corners, {self.square_mm:g} mm squares"

    def corners(self) -> np.ndarray:
        """(cols·rows, 3) float64 inner corners, board frame, mm, in detection order."""
        if self.charuco:
            return np.asarray(self._charuco_board().getChessboardCorners(), np.float64)
        gx, gy = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]) * self.square_mm

    def area_mm(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1): the squares of the printed pattern, board frame, mm."""
        s = self.square_mm
        if self.charuco:
            return 0.0, (self.cols + 1) * s, 0.0, (self.rows + 1) * s
        return -s, self.cols * s, -s, self.rows * s

    def _charuco_board(self):
        a = cv2.aruco
        dictionary = a.getPredefinedDictionary(getattr(a, self.charuco["dictionary"]))
        return a.CharucoBoard((self.cols + 1, self.rows + 1), self.square_mm,
                              self.charuco["marker_mm"], dictionary)


@dataclass(frozen=True)
class Detection:
    """Corners found in one view: board points ``obj`` (N, 3) and pixels ``img`` (N, 2), f64."""

    obj: np.ndarray
    img: np.ndarray
    detector: str = ""

    def __len__(self) -> int:
        return len(self.img)


def _spacing_px(img_pts: np.ndarray, cols: int, rows: int) -> float:
    g = img_pts.reshape(rows, cols, 2)
    d = [np.linalg.norm(np.diff(g, axis=a), axis=2).min() for a in (0, 1)]
    return float(min(d))


def _to_uint8(image: np.ndarray) -> np.ndarray:
    if image.dtype == np.uint8:
        return image
    img = image.astype(np.float32)
    lo, hi = np.percentile(img[::4, ::4], [0.5, 99.5])
    return np.clip((img - lo) * (255.0 / max(hi - lo, 1e-6)), 0, 255).astype(np.uint8)


def _grid_roughness(c: np.ndarray, cols: int, rows: int) -> float:
    """RMS, px, of the corners about a cubic in the grid indices (perspective and lens
    distortion are smooth over the board; detection noise is not)."""
    j, i = np.mgrid[0:rows, 0:cols]
    x, y = i.ravel() / cols, j.ravel() / rows
    A = np.column_stack([x**a * y**b for a in range(4) for b in range(4 - a)])
    r = c - A @ np.linalg.lstsq(A, c, rcond=None)[0]
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))


def find_chessboard(small: np.ndarray, size: tuple[int, int], detector: str
                    ) -> np.ndarray | None:
    """Unrefined (N, 2) corners by ``detector`` "sb" or "classic", or None if not found."""
    if detector == "sb":
        found, c = cv2.findChessboardCornersSB(
            small, size, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_NORMALIZE_IMAGE)
    else:
        found, c = cv2.findChessboardCorners(
            small, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    return c.reshape(-1, 2) if found else None


def _refine(img: np.ndarray, c: np.ndarray, scale: int, size: tuple[int, int]) -> np.ndarray:
    c = ((c + 0.5) * scale - 0.5).astype(np.float32)
    half = max(2, int(0.2 * _spacing_px(c, *size)))
    c = cv2.cornerSubPix(img, c.reshape(-1, 1, 2), (half, half), (-1, -1), _SUBPIX)
    return c.reshape(-1, 2).astype(np.float64)


def _detect_chessboard(img: np.ndarray, board: BoardSpec) -> Detection | None:
    size = (board.cols, board.rows)
    scale = 1
    while img.shape[1] / scale > _DETECT_MAX_WIDTH:
        scale *= 2
    small = img if scale == 1 else cv2.resize(img, None, fx=1 / scale, fy=1 / scale,
                                              interpolation=cv2.INTER_AREA)
    found = {}
    for name in ("sb", "classic"):
        c = find_chessboard(small, size, name)
        if c is None and scale > 1:
            c = find_chessboard(img, size, name)
            if c is not None:
                found[name] = _refine(img, c, 1, size)
        elif c is not None:
            found[name] = _refine(img, c, scale, size)
    if not found:
        return None
    if len(found) == 2:
        sb, cl = found["sb"], found["classic"]
        if np.abs(cl[::-1] - sb).mean() < np.abs(cl - sb).mean():
            found["classic"] = cl[::-1].copy()       # the other end of the grid first
    name = min(found, key=lambda k: _grid_roughness(found[k], *size))
    return Detection(board.corners(), found[name], name)


def _detect_charuco(img: np.ndarray, board: BoardSpec, min_corners: int = 6) -> Detection | None:
    cb = board._charuco_board()
    corners, ids, *_ = cv2.aruco.CharucoDetector(cb).detectBoard(img)
    if corners is None or ids is None or len(ids) < min_corners:
        return None
    obj, pts = cb.matchImagePoints(corners, ids)
    return Detection(np.asarray(obj, np.float64).reshape(-1, 3),
                     np.asarray(pts, np.float64).reshape(-1, 2), "charuco")


def detect_board(image: np.ndarray, board: BoardSpec) -> Detection | None:
    """The board's corners in ``image`` (H, W) uint8/uint16, or None if not found."""
    img = _to_uint8(np.asarray(image))
    return _detect_charuco(img, board) if board.charuco else _detect_chessboard(img, board)


@dataclass(frozen=True)
class View:
    """What became of one view: used in the final calibration or not, and why."""

    index: int
    name: str
    used: bool
    rms_px: float | None = None
    reason: str = ""
    detector: str = ""


@dataclass(frozen=True)
class Intrinsics:
    """Result of :func:`calibrate_intrinsics`. K (3, 3) px, dist (5,), image ``size`` (W, H);
    ``rms_px`` overall; ``views`` one per input view; ``std`` (9,) 1-σ of
    fx, fy, cx, cy, k1, k2, p1, p2, k3; ``poses`` board → camera (R (3, 3), t (3,) mm) of the
    used views by view index; ``residuals_px`` (N, 2) of all used corners."""

    K: np.ndarray
    dist: np.ndarray
    size: tuple[int, int]
    rms_px: float
    views: list[View]
    std: np.ndarray
    poses: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    residuals_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def used(self) -> list[View]:
        return [v for v in self.views if v.used]

    @property
    def rejected(self) -> list[View]:
        return [v for v in self.views if not v.used]


def _calibrate(dets: list[Detection], size: tuple[int, int]):
    obj = [d.obj.astype(np.float32) for d in dets]
    img = [d.img.astype(np.float32).reshape(-1, 1, 2) for d in dets]
    # A planar board needs an initial K for partial (ChArUco) views; OpenCV makes one itself.
    try:
        out = cv2.calibrateCameraExtended(obj, img, size, None, None)
    except cv2.error as e:
        raise CalibrationError(f"OpenCV could not calibrate from {len(dets)} views "
                               f"({str(e).strip().splitlines()[-1]})") from None
    rms, K, dist, rvecs, tvecs, std_in, _std_ex, per_view = out
    return float(rms), K, dist.ravel(), rvecs, tvecs, std_in.ravel(), per_view.ravel()


def calibrate_intrinsics(detections: list[Detection | None], size: tuple[int, int],
                         names: list[str] | None = None, outlier_factor: float = 3.0,
                         min_views: int = MIN_VIEWS) -> Intrinsics:
    """Calibrate from per-view detections (None: board not found in that view).

    size: (width, height) px. names: one per view for the report (default ``view i``).
    Views with RMS > outlier_factor × median RMS are dropped and the camera recalibrated.
    CalibrationError if fewer than ``min_views`` good views remain.
    """
    names = names or [f"view {i}" for i in range(len(detections))]
    reasons = {i: "board not found" for i, d in enumerate(detections) if d is None}
    for i, d in enumerate(detections):
        if d is not None and len(d) < 6:
            reasons[i] = f"only {len(d)} corners"
    rms_of: dict[int, float] = {}
    while True:
        keep = [i for i in range(len(detections)) if i not in reasons]
        if len(keep) < min_views:
            bad = ", ".join(f"{names[i]} ({r})" for i, r in sorted(reasons.items())[:4])
            more = f" and {len(reasons) - 4} more" if len(reasons) > 4 else ""
            raise CalibrationError(f"only {len(keep)} good views of {len(detections)}, need at "
                                   f"least {min_views}" + (f"; rejected: {bad}{more}" if bad else ""))
        rms, K, dist, rvecs, tvecs, std_in, per_view = _calibrate([detections[i] for i in keep],
                                                                   size)
        rms_of = dict(zip(keep, per_view.tolist()))
        limit = outlier_factor * float(np.median(per_view))
        worse = [i for i in keep if rms_of[i] > limit]
        if not worse:
            break
        for i in worse:
            reasons[i] = f"RMS {rms_of[i]:.3f} px > {outlier_factor:g} × median {limit / outlier_factor:.3f} px"
    views = [View(i, names[i], i not in reasons, rms_of.get(i), reasons.get(i, ""),
                  d.detector if d is not None else "") for i, d in enumerate(detections)]
    poses, res = {}, []
    for i, rv, tv in zip(keep, rvecs, tvecs):
        R, t = cv2.Rodrigues(rv)[0], np.asarray(tv, np.float64).ravel()
        poses[i] = (R, t)
        d = detections[i]
        proj, _ = cv2.projectPoints(d.obj, rv, tv, K, dist)
        res.append(proj.reshape(-1, 2) - d.img)
    n = 4 + len(dist)
    return Intrinsics(K, dist[:5] if len(dist) >= 5 else np.pad(dist, (0, 5 - len(dist))),
                      (int(size[0]), int(size[1])), rms, views, std_in[:min(n, 9)], poses,
                      np.concatenate(res))


def board_pose(det: Detection, K: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Board → camera pose (R (3, 3), t (3,) mm) of one view by solvePnP (IPPE, then LM),
    and its RMS reprojection error, px."""
    obj, img = det.obj.astype(np.float64), det.img.astype(np.float64)
    ok, rv, tv = cv2.solvePnP(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CalibrationError("solvePnP found no board pose")
    rv, tv = cv2.solvePnPRefineLM(obj, img, K, dist, rv, tv)
    proj, _ = cv2.projectPoints(obj, rv, tv, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))
    return cv2.Rodrigues(rv)[0], tv.ravel(), rms
