"""Read and grade the 2-D codes in a photograph that comes without a plan (a part marked
elsewhere, a verifier's test image): what ``insitu inspect PHOTO`` does without a cloud.

Each code zxing-cpp finds (:func:`insitu.vision.code_decode.read_codes`) is rectified by the
homography that maps its four corners — as zxing-cpp found them, then refined on the
module tiles — onto a square grid of :data:`PX_PER_MODULE` px a module with a quiet zone of
:data:`QUIET_MODULES`, and read again square-on from that picture. It is graded by
:func:`insitu.vision.dpm_grade.grade_symbol` against the module matrix zxing-cpp sampled
there (its symbol before error correction: a module damaged past recognition counts only
where our sampling disagrees with zxing's), and zxing-cpp's own unused error correction
(UEC, 0…1, ISO/IEC 15415's parameter) is graded beside it. A symbol on a curved part is not
flat under a homography: its grid nonuniformity says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from insitu.vision.code_decode import MATRIX_FORMATS, read_codes, stretch_u8
from insitu.vision.dpm_grade import Grades, grade_symbol, grade_uec, measure_grid

PX_PER_MODULE = 8
QUIET_MODULES = 2
SYMBOLOGY = {"QRCode": "qr", "MicroQRCode": "microqr", "DataMatrix": "datamatrix"}


@dataclass(frozen=True)
class PhotoCode:
    """One code read in a photograph. ``text`` as decoded; ``symbology`` (qr, microqr,
    datamatrix); ``corners`` (4, 2) px in the photo, the symbol's top-left, top-right,
    bottom-right, bottom-left; ``matrix`` (rows, cols) bool, True = a dark (marked) module as
    sampled; ``module_px`` the mean module pitch in the photo, px; ``uec`` zxing-cpp's unused
    error correction 0…1 (None: not reported); ``grades`` of the rectified ``picture``
    (H, W) float32 (NaN: outside the photo)."""

    text: str
    symbology: str
    corners: np.ndarray
    matrix: np.ndarray
    module_px: float
    uec: float | None
    grades: Grades
    picture: np.ndarray

    @property
    def uec_grade(self) -> int | None:
        """UEC graded 4…0 (A ≥ 0.62, B ≥ 0.50, C ≥ 0.37, D ≥ 0.25, ISO/IEC 15415)."""
        return None if self.uec is None else grade_uec(self.uec)

    @property
    def overall(self) -> int:
        """The lowest of the grades and the UEC grade."""
        return min(g for g in (self.grades.overall, self.uec_grade) if g is not None)


def _corners(code, scale: float) -> np.ndarray:
    p = code.position
    pts = (p.top_left, p.top_right, p.bottom_right, p.bottom_left)
    return np.array([[q.x, q.y] for q in pts], np.float64) / scale


def _outer(rows: int, cols: int) -> np.ndarray:
    """(4, 2) float32: the symbol's outer corners in the rectified picture, px."""
    s, q = PX_PER_MODULE, QUIET_MODULES
    return np.array([[q, q], [q + cols, q], [q + cols, q + rows], [q, q + rows]],
                    np.float32) * s - 0.5


CENTRE00 = np.full(2, (QUIET_MODULES + 0.5) * PX_PER_MODULE - 0.5)
"""Module (0, 0)'s centre in the rectified picture, px."""


def _grade(picture: np.ndarray, matrix: np.ndarray, symbology: str) -> Grades:
    step = float(PX_PER_MODULE)
    return grade_symbol(picture, matrix, CENTRE00, np.array([step, 0.0]),
                        np.array([0.0, step]), symbology, True)


def rectify_symbol(grey: np.ndarray, corners: np.ndarray, rows: int, cols: int
                   ) -> np.ndarray:
    """The symbol whose outer corners (4, 2) px (top-left, top-right, bottom-right,
    bottom-left) lie in ``grey`` (H, W) warped onto (rows + 2q) × (cols + 2q) modules of
    :data:`PX_PER_MODULE` px (q = :data:`QUIET_MODULES`), float32, NaN outside the photo.
    Module (0, 0)'s centre is at ((q + ½) s − ½, (q + ½) s − ½) px, s = PX_PER_MODULE."""
    s, q = PX_PER_MODULE, QUIET_MODULES
    H = cv2.getPerspectiveTransform(corners.astype(np.float32), _outer(rows, cols))
    size = ((cols + 2 * q) * s, (rows + 2 * q) * s)
    return cv2.warpPerspective(grey.astype(np.float32), H, size, flags=cv2.INTER_LINEAR,
                               borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)


def _refined(grey: np.ndarray, corners: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """The symbol's corners (4, 2) px moved to where its modules are: zxing-cpp gives them to
    the whole pixel, a fifth of a module on a small symbol, which sways the grades with the
    photo's turn. The symbol rectified by ``corners``, its tiles found
    (:func:`insitu.vision.dpm_grade.measure_grid`), an affine grid fitted to them, and its
    outer corners carried back into the photo. ``corners`` unchanged when fewer than three
    tiles are found."""
    rows, cols = matrix.shape
    s = PX_PER_MODULE
    picture = rectify_symbol(grey, corners, rows, cols)
    filled = np.where(np.isfinite(picture), picture, np.nanmedian(picture)).astype(np.float32)
    mods, found, score = measure_grid(filled, matrix, CENTRE00, np.array([s, 0.0]),
                                      np.array([0.0, s]))
    good = score > 0.3
    if good.sum() < 3:
        return corners
    A = np.column_stack([mods[good], np.ones(good.sum())])
    coef, *_ = np.linalg.lstsq(A, found[good], rcond=None)
    outer = np.array([[-0.5, -0.5, 1], [cols - 0.5, -0.5, 1], [cols - 0.5, rows - 0.5, 1],
                      [-0.5, rows - 0.5, 1]]) @ coef                 # rectified px
    H = cv2.getPerspectiveTransform(corners.astype(np.float32), _outer(rows, cols))
    return cv2.perspectiveTransform(outer[None].astype(np.float64), np.linalg.inv(H))[0]


def _reread(picture: np.ndarray, code, matrix: np.ndarray, inverted: bool):
    """The code read again from its rectified ``picture``: square-on, 8 px a module, its quiet
    zone made plain ground. The first read samples the photo on the grid its detector
    found, a fraction of a module off at a corner on a small symbol: modules it samples wrong
    are hidden by the error correction but would count against the print (and sway with
    the photo's turn). None unless it reads the same text in a matrix of the same size that
    agrees with the first in 80 % of its modules."""
    import zxingcpp

    rows, cols = matrix.shape
    s, q = PX_PER_MODULE, QUIET_MODULES
    img = stretch_u8(picture)
    ground = ~np.isfinite(picture)
    ground[:q * s] = ground[(q + rows) * s:] = True
    ground[:, :q * s] = ground[:, (q + cols) * s:] = True
    img[ground] = 0 if inverted else 255
    found = [b for b in zxingcpp.read_barcodes(img, formats=code.format) if b.valid]
    if not found or found[0].text != code.text:
        return None
    again = np.asarray(found[0].to_image(add_quiet_zones=False)) < 128
    if again.shape != matrix.shape or np.mean(again == matrix) < 0.8:
        return None
    return found[0]


def read_photo(image: np.ndarray) -> tuple[PhotoCode, ...]:
    """Every QR, Micro QR and Data Matrix code in ``image`` ((H, W) grey or (H, W, 3) BGR, any
    depth), decoded and graded; () when none is read."""
    grey = np.asarray(image)
    if grey.ndim == 3:
        grey = cv2.cvtColor(grey, cv2.COLOR_BGR2GRAY if grey.shape[2] == 3
                            else cv2.COLOR_BGRA2GRAY)
    found, scale = read_codes(grey, MATRIX_FORMATS)
    out = []
    for code in found:
        if code.format.name not in SYMBOLOGY:
            continue
        matrix = np.asarray(code.to_image(add_quiet_zones=False)) < 128
        rows, cols = matrix.shape
        corners = _corners(code, scale)
        sides = np.linalg.norm(corners - np.roll(corners, -1, axis=0), axis=1)
        module_px = float(np.mean([sides[0] / cols, sides[1] / rows, sides[2] / cols,
                                   sides[3] / rows]))
        corners = _refined(grey, corners, matrix)
        picture = rectify_symbol(grey, corners, rows, cols)
        symbology = SYMBOLOGY[code.format.name]
        grades = _grade(picture, matrix, symbology)
        again = _reread(picture, code, matrix, grades.inverted)
        if again is not None:
            code, matrix = again, np.asarray(again.to_image(add_quiet_zones=False)) < 128
            grades = _grade(picture, matrix, symbology)
        uec = code.extra.get("UEC") if isinstance(code.extra, dict) else None
        out.append(PhotoCode(code.text, symbology, corners, matrix, module_px,
                             None if uec is None else float(uec), grades, picture))
    return tuple(out)


def photo_picture(codes: tuple[PhotoCode, ...]) -> np.ndarray:
    """(H, W) uint8: the rectified symbols side by side, each stretched to its own 1st…99th
    percentile (unseen: black)."""
    tiles = [np.where(np.isfinite(c.picture), stretch_u8(c.picture), 0) for c in codes]
    h = max(t.shape[0] for t in tiles)
    return np.hstack([np.pad(t, ((0, h - t.shape[0]), (0, PX_PER_MODULE)))
                      for t in tiles]).astype(np.uint8)
