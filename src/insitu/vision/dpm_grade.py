"""Print quality of a marked 2-D code in the spirit of ISO/IEC TR 29158 (direct part marking)
and ISO/IEC 15415, measured on a rectified picture of the mark.

What is measured, and how it differs from the standards' exact methods:

* **Grid**: the standards sample the grid the reference decoder found. Here the symbol's
  planned module matrix is matched, tile by tile (4 × 4 modules, normalised cross-correlation
  with sub-pixel peaks), against the picture; an affine grid is fitted to the tile positions.
  **Axial nonuniformity** AN = |X − Y| / ((X + Y) / 2) of the fitted module pitches along the
  two axes (15415's definition). **Grid nonuniformity** GN = the largest distance of a tile's
  position from the fitted grid, in module pitches (15415 measures every grid intersection;
  a tile averages 16 modules, so this reads lower on a locally distorted mark).
* **Cell contrast** CC = (ML − MD) / ML, ML, MD the mean light and dark module reflectances
  (29158 §7.3, the picture's grey values: scale-free, no calibrated reflectance).
* **Cell modulation** and **reflectance margin**: each module's MOD = 2 |R − GT| / |ML − MD|
  (GT = (ML + MD) / 2 times the light where the module lies, :func:`_light`: a shadow or
  glare across the mark moves the threshold with it — ISO's verifier lights evenly, a side
  camera or a photo does not — a print fault does not; the span |ML − MD| stays the
  symbol's, so the contrast a shadow takes still lowers the modulation)
  graded A ≥ 0.50, B ≥ 0.40, C ≥ 0.30, D ≥ 0.20; the margin grades a
  module on the wrong side of GT (against the plan) F. The standards grade codewords and
  weigh them against the unused error correction; here the share of modules below each level
  is weighed against a symbology's module budget (:data:`MODULE_BUDGET`, an estimate from
  its error-correction capacity), and the grade is the highest of min(level, that UEC grade).
* **Fixed-pattern damage**: modules of the finder patterns (QR, Micro QR: each 8 × 8 finder
  with its separator) or the L finder and clock track (Data Matrix: each outer edge) on the
  wrong side of GT; the worst segment's count graded 0 A, 1 B, 2 C, 3 D, more F (ISO/IEC
  18004's finder rule, applied to every segment; 15415's Data Matrix segment rule is
  finer). Not graded for Code 128.
* Code 128 is a linear symbol (ISO/IEC 15416 grades it by scan reflectance profiles): its
  bars are graded here as modules (contrast, modulation, margin, decode); axial and grid
  nonuniformity do not apply (None).
* **Decode**: A when the reader decoded the symbol, else F.

Each parameter is graded 4…0 (A…F); the overall grade is the lowest.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

LETTERS = "FDCBA"
MODULE_BUDGET = {"qr": 0.04, "microqr": 0.025, "datamatrix": 0.06, "code128": 0.01}
_MOD = (0.50, 0.40, 0.30, 0.20)        # module modulation for A, B, C, D
_UEC = (0.62, 0.50, 0.37, 0.25)
_CC = (0.30, 0.25, 0.20, 0.15)
_AN = (0.06, 0.08, 0.10, 0.12)
_GN = (0.38, 0.50, 0.63, 0.75)
TILE = 4                               # modules per tile side of the grid measurement
FIXED_SYMBOLOGIES = ("qr", "microqr", "datamatrix")     # 2-D matrix codes: a module grid


def letter(grade: int) -> str:
    """4 … 0 → "A" … "F"."""
    return LETTERS[int(grade)]


def _at_least(value: float, limits) -> int:
    """4 when value ≥ limits[0], 3 when ≥ limits[1], …, 0 below all."""
    return next((4 - i for i, t in enumerate(limits) if value >= t), 0)


def _at_most(value: float, limits) -> int:
    return next((4 - i for i, t in enumerate(limits) if value <= t), 0)


@dataclass(frozen=True)
class Grades:
    """The grades 4 … 0 of one symbol and the values behind them: ``cell_contrast`` CC,
    ``axial_nonuniformity`` AN, ``grid_nonuniformity`` GN (module pitches), ``fixed_errors``
    (modules wrong in the worst fixed-pattern segment; None: not graded), ``inverted``: the
    marks are lighter than the ground. ``overall`` is the lowest grade."""

    decode: int
    cell_contrast: float
    cell_contrast_grade: int
    cell_modulation: int
    reflectance_margin: int
    fixed_errors: int | None
    fixed_pattern: int | None
    axial_nonuniformity: float | None
    axial_grade: int | None
    grid_nonuniformity: float | None
    grid_grade: int | None
    inverted: bool

    @property
    def overall(self) -> int:
        return min(g for g in (self.decode, self.cell_contrast_grade, self.cell_modulation,
                               self.reflectance_margin, self.fixed_pattern, self.axial_grade,
                               self.grid_grade) if g is not None)

    def summary(self) -> str:
        """One line: overall letter and each parameter's."""
        fpd = "" if self.fixed_pattern is None else f", FPD {letter(self.fixed_pattern)}"
        grid = ("" if self.axial_grade is None else
                f", AN {self.axial_nonuniformity:.3f} {letter(self.axial_grade)}, GN "
                f"{self.grid_nonuniformity:.2f} {letter(self.grid_grade)}")
        return (f"{letter(self.overall)} (decode {letter(self.decode)}, CC "
                f"{self.cell_contrast:.2f} {letter(self.cell_contrast_grade)}, CM "
                f"{letter(self.cell_modulation)}, RM {letter(self.reflectance_margin)}"
                f"{fpd}{grid})")


def fixed_segments(symbology: str, rows: int, cols: int) -> list[np.ndarray]:
    """Fixed-pattern segments of a symbol: (rows, cols) bool masks, row 0 at the top."""
    def box(r0, r1, c0, c1):
        m = np.zeros((rows, cols), bool)
        m[max(r0, 0):min(r1, rows), max(c0, 0):min(c1, cols)] = True
        return m
    if symbology == "qr":
        return [box(0, 8, 0, 8), box(0, 8, cols - 8, cols), box(rows - 8, rows, 0, 8)]
    if symbology == "microqr":
        return [box(0, 8, 0, 8)]
    if symbology == "datamatrix":
        return [box(0, rows, 0, 1), box(rows - 1, rows, 0, cols), box(0, 1, 0, cols),
                box(0, rows, cols - 1, cols)]
    return []


def _ideal(matrix: np.ndarray, pitch: float, pad: int) -> np.ndarray:
    """float32 picture of ``matrix`` (True dark = 0, light = 1) at ``pitch`` px per module,
    axis-aligned, ``pad`` light modules around."""
    m = np.pad(~matrix, pad, constant_values=True).astype(np.float32)
    n = max(1, int(round(pitch * 8)))
    big = cv2.resize(m, (m.shape[1] * n, m.shape[0] * n), interpolation=cv2.INTER_NEAREST)
    return cv2.resize(big, (int(round(m.shape[1] * pitch)), int(round(m.shape[0] * pitch))),
                      interpolation=cv2.INTER_AREA)


def _peak(res: np.ndarray) -> tuple[float, float, float]:
    """(x, y, value) of the largest |res| with a parabolic sub-pixel refinement."""
    y, x = np.unravel_index(int(np.argmax(np.abs(res))), res.shape)
    val = float(res[y, x])
    a = np.abs(res)

    def refine(m, p, q, n):
        if 0 < p < n - 1:
            d = m(p - 1) - 2 * m(p) + m(p + 1)
            return p + (0.5 * (m(p - 1) - m(p + 1)) / d if d < 0 else 0.0)
        return float(p)
    return (refine(lambda k: a[y, k], x, 0, res.shape[1]),
            refine(lambda k: a[k, x], y, 0, res.shape[0]), val)


def measure_grid(picture: np.ndarray, matrix: np.ndarray, centre00: np.ndarray,
                 col_step: np.ndarray, row_step: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tile positions of the symbol in ``picture`` (H, W) float (no NaN): each TILE × TILE
    block of ``matrix`` (rows, cols) drawn ideally is matched around where the nominal grid
    (pixel centre of module (0, 0), steps (2,) px per column and per row) puts it. The grid
    must be axis-aligned (steps along +x and +y). Returns the tiles' module positions
    (T, 2) (col, row of their centres), their found pixel positions (T, 2) and |ncc| (T,)."""
    pitch = float((np.linalg.norm(col_step) + np.linalg.norm(row_step)) / 2)
    pad = max(2, int(np.ceil(0.5 * pitch)))
    rows, cols = matrix.shape
    mods, found, score = [], [], []
    for r0 in range(0, rows, TILE):
        for c0 in range(0, cols, TILE):
            block = matrix[r0:r0 + TILE, c0:c0 + TILE]
            if not _two_way(block):
                continue
            tmpl = _ideal(block, pitch, 0)
            tl = centre00 + (c0 - 0.5) * col_step + (r0 - 0.5) * row_step    # tile corner
            x0, y0 = int(np.floor(tl[0])) - pad, int(np.floor(tl[1])) - pad
            win = picture[max(y0, 0):y0 + tmpl.shape[0] + 2 * pad + 1,
                          max(x0, 0):x0 + tmpl.shape[1] + 2 * pad + 1]
            if (x0 < 0 or y0 < 0 or win.shape[0] < tmpl.shape[0] + 2
                    or win.shape[1] < tmpl.shape[1] + 2 or win.std() < 1e-6):
                continue
            res = cv2.matchTemplate(win.astype(np.float32), tmpl, cv2.TM_CCOEFF_NORMED)
            px, py, val = _peak(res)
            if not (0 < px < res.shape[1] - 1 and 0 < py < res.shape[0] - 1):
                continue                                # at the window's edge: not found
            mods.append([c0 + (block.shape[1] - 1) / 2, r0 + (block.shape[0] - 1) / 2])
            found.append([x0 + px + (tmpl.shape[1] - 1) / 2, y0 + py + (tmpl.shape[0] - 1) / 2])
            score.append(abs(val))
    return np.array(mods).reshape(-1, 2), np.array(found).reshape(-1, 2), np.array(score)


def _two_way(block: np.ndarray) -> bool:
    """The block has edges both across and along its rows (it locates in x and in y)."""
    return bool(np.any(block[:, 1:] != block[:, :-1]) and np.any(block[1:] != block[:-1])
                and min(np.sum(block[:, 1:] != block[:, :-1]),
                        np.sum(block[1:] != block[:-1])) >= 2)


def _module_grade(mod: np.ndarray) -> np.ndarray:
    return np.select([mod >= t for t in _MOD], [4, 3, 2, 1], 0)


def grade_uec(uec: float) -> int:
    """Unused error correction 0…1 graded 4…0 (A ≥ 0.62, B ≥ 0.50, C ≥ 0.37, D ≥ 0.25)."""
    return _at_least(uec, _UEC)


def _uec_grade(module_grades: np.ndarray, budget: float) -> int:
    """max over levels L of min(L, grade of 1 − share of modules below L / budget)."""
    best = 0
    for level in (4, 3, 2, 1):
        uec = 1.0 - float(np.mean(module_grades < level)) / budget
        best = max(best, min(level, grade_uec(uec)))
    return best


def _local_shift(mods: np.ndarray, residual: np.ndarray, jj: np.ndarray, ii: np.ndarray,
                 pitch: float) -> np.ndarray:
    """(rows, cols, 2) px: the tiles' departures from the affine grid (T, 2) at their module
    positions (T, 2) carried smoothly to every module (thin-plate spline, smoothed), so a
    symbol on a curved part or under lens distortion is sampled on its modules; (0, 0) where
    the departures are within a tenth of a module or too few tiles tell them."""
    if len(mods) < 6 or np.max(np.linalg.norm(residual, axis=1)) < 0.1 * pitch:
        return np.zeros((*jj.shape, 2))
    from scipy.interpolate import RBFInterpolator

    field = RBFInterpolator(mods, residual, kernel="thin_plate_spline", degree=1,
                            smoothing=float(len(mods)))
    return field(np.column_stack([jj.ravel(), ii.ravel()])).reshape(*jj.shape, 2)


SHADING_MODULES = 4.0                  # the light's shading is smoothed over this many modules


def _light(R: np.ndarray, matrix: np.ndarray, visible: np.ndarray, ML: float, MD: float
           ) -> np.ndarray:
    """(rows, cols): the light falling where each module lies, relative to the symbol's
    mean — the change the light and the dark modules' values (each smoothed over
    :data:`SHADING_MODULES`, Gaussian σ, normalised) share: both darker in a shadow, both
    lighter in glare, the smaller relative change of the two; 1 where they disagree. A print
    fault moves one of them only (growth darkens the small light modules, a weak burn lightens
    the dark ones) and is not taken for light."""
    from scipy.ndimage import gaussian_filter

    rel = []
    for cls, mean in ((~matrix & visible, ML), (matrix & visible, MD)):
        w = gaussian_filter(cls.astype(float), SHADING_MODULES, mode="constant")
        v = gaussian_filter(np.where(cls, R, 0.0), SHADING_MODULES, mode="constant")
        rel.append(np.where(w > 1e-3, v / np.maximum(w, 1e-3) / max(mean, 1e-9) - 1, 0.0))
    rl, rd = rel
    return 1 + np.where(rl * rd > 0, np.sign(rl) * np.minimum(np.abs(rl), np.abs(rd)), 0.0)


def grade_symbol(picture: np.ndarray, matrix: np.ndarray, centre00: np.ndarray,
                 col_step: np.ndarray, row_step: np.ndarray, symbology: str,
                 decoded: bool) -> Grades:
    """Grade the symbol whose planned modules ``matrix`` (rows, cols) bool (True dark, row 0
    at the top) lie in ``picture`` (H, W) float (NaN: not seen) on the nominal grid
    ``centre00`` (2,) px + column / row steps (2,) px, axis-aligned. See the module
    docstring."""
    pic = np.asarray(picture, np.float32)
    seen = np.isfinite(pic)
    fill = float(np.nanmedian(pic)) if seen.any() else 0.0
    pic = np.where(seen, pic, fill).astype(np.float32)
    rows, cols = matrix.shape
    jj, ii = np.meshgrid(np.arange(cols), np.arange(rows))
    nominal = centre00 + jj[..., None] * col_step + ii[..., None] * row_step
    pitch = float((np.linalg.norm(col_step) + np.linalg.norm(row_step)) / 2)
    linear = symbology not in FIXED_SYMBOLOGIES
    mods, found, score = (measure_grid(pic, matrix, centre00, col_step, row_step) if not linear
                          else (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)))
    good = score > 0.3
    if good.sum() >= 3:
        A = np.column_stack([mods[good], np.ones(good.sum())])
        coef, *_ = np.linalg.lstsq(A, found[good], rcond=None)
        fitted = A @ coef
        pu, pv = np.linalg.norm(coef[0]), np.linalg.norm(coef[1])
        an = abs(pu - pv) / ((pu + pv) / 2)
        gn = float(np.max(np.linalg.norm(found[good] - fitted, axis=1))) / pitch
        centres = np.stack([jj, ii, np.ones_like(jj)], -1) @ coef
        centres += _local_shift(mods[good], found[good] - fitted, jj, ii, pitch)
    else:
        an, gn, centres = 1.0, 1.0, nominal
    k = max(1, int(round(0.5 * pitch)))
    box = cv2.blur(pic, (k, k))
    seen_box = cv2.blur(seen.astype(np.float32), (k, k)) > 0.99
    coords = [centres[..., 1].ravel(), centres[..., 0].ravel()]
    R = map_coordinates(box, coords, order=1, mode="nearest").reshape(rows, cols)
    visible = map_coordinates(seen_box.astype(np.float32), coords, order=0,
                              mode="constant").reshape(rows, cols) > 0.5
    ML = float(np.mean(R[~matrix & visible])) if (~matrix & visible).any() else 0.0
    MD = float(np.mean(R[matrix & visible])) if (matrix & visible).any() else 0.0
    inverted = MD > ML
    span = abs(ML - MD)
    cc = span / max(ML, MD, 1e-9)
    gt = (ML + MD) / 2 * _light(R, matrix, visible, ML, MD)
    mod = np.where(visible, 2 * np.abs(R - gt) / max(span, 1e-9), 0.0)
    mgrade = _module_grade(mod)
    dark = (R < gt) != inverted
    wrong = (dark != matrix) | ~visible
    margin = np.where(wrong, 0, mgrade)
    budget = MODULE_BUDGET.get(symbology, 0.02)
    segs = fixed_segments(symbology, rows, cols)
    errors = max((int(np.sum(wrong & s)) for s in segs), default=None)
    return Grades(
        decode=4 if decoded else 0, cell_contrast=cc, cell_contrast_grade=_at_least(cc, _CC),
        cell_modulation=_uec_grade(mgrade, budget), reflectance_margin=_uec_grade(margin, budget),
        fixed_errors=errors, fixed_pattern=None if errors is None else max(0, 4 - errors),
        axial_nonuniformity=None if linear else float(an),
        axial_grade=None if linear else _at_most(an, _AN),
        grid_nonuniformity=None if linear else float(gn),
        grid_grade=None if linear else _at_most(gn, _GN), inverted=bool(inverted))
