"""Generated patterns: codes — QR (segno), Data Matrix ECC 200, Micro QR and Code 128
(zxing-cpp) — and fiducial grids for calibration, in mm, y up.

A code is one filled square per dark module (corners exact), origin at the bottom-left of
its quiet zone; the pattern's frame is the symbol with its quiet zone (kept clear, counted in
the bounds) and its ``code`` says what it encodes, so placement sizes the symbol without the
quiet zone and the verifier knows what it must read."""

from __future__ import annotations

import math

import numpy as np

from insitu.errors import FormatError
from insitu.patterns.model import Code, Pattern, contours_of
from insitu.patterns.raster import mask_region
from insitu.patterns.vector import _arc_steps

EC_LEVELS = ("L", "M", "Q", "H")


def qr_matrix(data: str, error: str = "M", quiet_zone: int = 4) -> np.ndarray:
    """(n, n) bool module matrix (True = dark), including ``quiet_zone`` light modules all
    round. ``error`` is the error-correction level L, M, Q or H (kept exactly, not boosted)."""
    import segno

    level = str(error).upper()
    if level not in EC_LEVELS:
        raise FormatError(f"qr:{data!r}: error correction must be one of L, M, Q, H, "
                          f"got {error!r}")
    if not data:
        raise FormatError("qr:\"\": no data to encode (empty pattern)")
    if int(quiet_zone) != quiet_zone or quiet_zone < 0:
        raise FormatError(f"qr:{data!r}: quiet zone must be a whole number of modules ≥ 0, "
                          f"got {quiet_zone}")
    try:
        qr = segno.make_qr(data, error=level.lower(), boost_error=False)
    except Exception as e:  # noqa: BLE001 — segno's DataOverflowError and friends
        raise FormatError(f"qr:{data[:40]!r}: cannot encode ({e})") from e
    m = np.array([list(row) for row in qr.matrix], np.uint8) & 1
    return np.pad(m.astype(bool), int(quiet_zone))


def qr_pattern(data: str, error: str = "M", quiet_zone: int = 4, module_mm: float = 1.0,
               invert: bool = False) -> Pattern:
    """A QR code as filled contours: one square of ``module_mm`` per dark module, corners
    exact, origin at the bottom-left of the quiet zone; the frame is the whole symbol with its
    quiet zone, so scaling keeps the margin. ``invert=True`` fills the light modules and the
    quiet zone instead (for marks that come out light on a dark surface)."""
    if not module_mm > 0:
        raise FormatError(f"qr:{data!r}: module size must be > 0 mm, got {module_mm}")
    m = qr_matrix(data, error, quiet_zone)
    if invert:
        m = ~m
    n = m.shape[0]
    frame = np.array([[0, 0], [n, 0], [n, n], [0, n]], np.float64) * module_mm
    k = n - 2 * int(quiet_zone)
    return Pattern(tuple(contours_of(mask_region(m, module_mm))), (),
                   f"qr:{data}", frame, Code("qr", data, k, k, int(quiet_zone)))


# zxing-cpp symbologies: name → (BarcodeFormat attribute, default quiet zone in modules)
SYMBOLOGIES = {"datamatrix": ("DataMatrix", 2), "microqr": ("MicroQRCode", 2),
               "code128": ("Code128", 10), "qr": ("QRCode", 4)}


def zxing_matrix(symbology: str, data: str, *, ec: str | None = None, gs1: bool = False,
                 square: bool = True, aspect: float = 0.25) -> np.ndarray:
    """(rows, cols) bool module matrix (True = dark) without quiet zone, written by
    zxing-cpp. Data Matrix: ``gs1`` (FNC1 + element strings "(01)…(21)…"), ``square``
    symbols; Micro QR: ``ec`` L|M|Q; Code 128: bars ``aspect`` × the symbol's width tall."""
    import zxingcpp

    where = f"{symbology}:{data[:40]!r}"
    if not data:
        raise FormatError(f"{symbology}:\"\": no data to encode (empty pattern)")
    kw: dict = {}
    if symbology == "datamatrix":
        kw = {"gs1": bool(gs1), "force_square": bool(square)}
    elif ec is not None:
        if str(ec).upper() not in ("L", "M", "Q"):
            raise FormatError(f"{where}: error correction must be one of L, M, Q, got {ec!r}")
        kw = {"ec_level": str(ec).upper()}
    fmt = getattr(zxingcpp.BarcodeFormat, SYMBOLOGIES[symbology][0])
    try:
        img = zxingcpp.create_barcode(data, fmt, **kw).to_image(scale=1,
                                                                add_quiet_zones=False)
    except Exception as e:  # noqa: BLE001 — zxing-cpp's encoder errors, one line
        raise FormatError(f"{where}: cannot encode ({' '.join(str(e).split())[:120]})") from e
    m = np.asarray(img) < 128
    if symbology == "code128":
        if not 0 < aspect <= 10:
            raise FormatError(f"{where}: aspect must be in (0, 10], got {aspect}")
        bars = m[m.shape[0] // 2]
        m = np.repeat(bars[None, :], max(1, round(aspect * len(bars))), axis=0)
    return m


def code_pattern(symbology: str, data: str, module_mm: float = 1.0,
                 quiet_zone: int | None = None, **options) -> Pattern:
    """A code of :data:`SYMBOLOGIES` as filled module squares of ``module_mm`` with
    ``quiet_zone`` light modules all round (default: the symbology's); ``options`` go to
    :func:`zxing_matrix`."""
    if not module_mm > 0:
        raise FormatError(f"{symbology}:{data[:40]!r}: module size must be > 0 mm, got "
                          f"{module_mm}")
    q = SYMBOLOGIES[symbology][1] if quiet_zone is None else quiet_zone
    if int(q) != q or q < 0:
        raise FormatError(f"{symbology}:{data[:40]!r}: quiet zone must be a whole number of "
                          f"modules ≥ 0, got {q}")
    m = zxing_matrix(symbology, data, **options)
    rows, cols = m.shape
    w, h = (cols + 2 * q) * module_mm, (rows + 2 * q) * module_mm
    frame = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float64)
    g = mask_region(np.pad(m, int(q)), module_mm)
    return Pattern(tuple(contours_of(g)), (), f"{symbology}:{data}", frame,
                   Code(symbology, data, cols, rows, int(q)))


def fiducial_centres(rows: int, cols: int, pitch_mm: float) -> np.ndarray:
    """(rows·cols, 2) float64 mm grid centres, row-major from the bottom-left, centred on
    (0, 0)."""
    j, i = np.meshgrid(np.arange(cols), np.arange(rows))
    xy = np.column_stack([j.ravel() - (cols - 1) / 2.0, i.ravel() - (rows - 1) / 2.0])
    return xy * pitch_mm


def circle(centre, radius: float, tol_mm: float = 0.002) -> np.ndarray:
    """(N, 2) polygon inscribed in a circle, CCW, chords within ``tol_mm`` of it and within
    2e-4 of the radius (so small fiducials keep their area to 3e-4)."""
    n = max(8, _arc_steps(radius, 2 * math.pi, tol_mm))
    n = -(-n // 4) * 4  # a vertex at each extreme: the bounding box is exact
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.column_stack([np.cos(a), np.sin(a)]) * radius + np.asarray(centre, np.float64)


def fiducial_grid(rows: int = 5, cols: int = 5, pitch_mm: float = 5.0,
                  diameter_mm: float = 1.0, filled: bool = True,
                  tol_mm: float = 0.002) -> Pattern:
    """Circles of ``diameter_mm`` on a rows × cols grid of ``pitch_mm``, centred on (0, 0):
    filled contours (``filled``) or closed circle lines (paths). Centres are
    :func:`fiducial_centres`."""
    if rows < 1 or cols < 1 or not pitch_mm > 0 or not diameter_mm > 0:
        raise FormatError(f"fiducial grid: need rows, cols ≥ 1 and pitch, diameter > 0 mm, got "
                          f"{rows}×{cols}, pitch {pitch_mm}, diameter {diameter_mm}")
    if diameter_mm >= pitch_mm and (rows > 1 or cols > 1):
        raise FormatError(f"fiducial grid: diameter {diameter_mm} mm must be below the pitch "
                          f"{pitch_mm} mm")
    rings = [circle(c, diameter_mm / 2.0, tol_mm) for c in fiducial_centres(rows, cols,
                                                                            pitch_mm)]
    name = f"fiducials {rows}x{cols} @ {pitch_mm:g} mm"
    if filled:
        return Pattern(tuple(rings), (), name)
    return Pattern((), tuple(np.vstack([r, r[:1]]) for r in rings), name)
