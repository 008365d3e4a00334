"""The read-back picture: each mark rectified onto its surface (:mod:`.readback`), the plan's
outlines over it in thin orange lines, unseen pixels hatched blue, mm axes along the
pattern's own u, v, and what was read (decoded text, offset, grade) above it. OpenCV
drawing; BGR uint8."""

from __future__ import annotations

import math

import cv2
import numpy as np

from insitu.marking.readback import MarkReading
from insitu.vision.code_decode import stretch_u8
from insitu.vision.dpm_grade import letter

PANEL_PX = 520             # the picture's longer side on the panel, px
_LEFT, _TOP, _BOTTOM, _RIGHT = 56, 74, 40, 16
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_INK, _PLAN, _UNSEEN = (30, 30, 30), (0, 140, 255), (200, 120, 60)
_GOOD, _BAD = (40, 140, 40), (30, 30, 210)


def _tick(span: float) -> float:
    """A 1, 2 or 5 × 10^k step giving 4 … 10 ticks over ``span`` mm."""
    e = 10.0 ** math.floor(math.log10(span / 4))
    return next(m * e for m in (1, 2, 5, 10) if span / (m * e) <= 10)


def _grey(picture: np.ndarray) -> np.ndarray:
    """float picture (NaN unseen) → BGR uint8 stretched over its 1 … 99 % values, unseen
    pixels hatched."""
    seen = np.isfinite(picture)
    g = stretch_u8(picture) if seen.any() else np.zeros(picture.shape, np.uint8)
    img = cv2.cvtColor(g, cv2.COLOR_GRAY2BGR)
    rr, cc = np.indices(picture.shape)
    img[~seen & ((rr + cc) % 6 < 3)] = _UNSEEN
    img[~seen & ((rr + cc) % 6 >= 3)] = (235, 225, 215)
    return img


def reading_lines(r: MarkReading) -> list[tuple[str, tuple[int, int, int]]]:
    """The panel's title lines, each with its colour."""
    lines = [(r.name[:60], _INK)]
    if r.text is not None:
        if r.decoded is None:
            lines.append(("NOT decoded", _BAD))
        else:
            same = "= plan" if r.ok else "!= plan " + repr(r.text)[:30]
            lines.append((f"read {r.decoded[:40]!r} {same}", _GOOD if r.ok else _BAD))
    off = ("mark not found" if r.offset_mm is None else
           "offset u {:+.3f} v {:+.3f} mm".format(*r.offset_mm))
    grade = "" if r.grades is None else f"   grade {letter(r.grades.overall)}"
    lines.append((off + grade, _INK))
    return lines


def reading_panel(r: MarkReading) -> np.ndarray:
    """One mark's panel, BGR uint8."""
    h, w = r.picture.shape
    s = PANEL_PX / max(h, w)
    pic = cv2.resize(_grey(r.picture), (round(w * s), round(h * s)),
                     interpolation=cv2.INTER_NEAREST if s >= 2 else cv2.INTER_AREA)
    ph, pw = pic.shape[:2]
    img = np.full((ph + _TOP + _BOTTOM, pw + _LEFT + _RIGHT, 3), 255, np.uint8)
    img[_TOP:_TOP + ph, _LEFT:_LEFT + pw] = pic
    k = s / r.frame.px_mm                                   # panel px per mm
    shift = 4
    for p in r.plan:
        xy = np.column_stack([_LEFT + p[:, 0] * k, _TOP + ph - p[:, 1] * k])
        cv2.polylines(img, [np.round(xy * (1 << shift)).astype(np.int32)], False, _PLAN, 1,
                      cv2.LINE_AA, shift)
    cv2.rectangle(img, (_LEFT, _TOP), (_LEFT + pw, _TOP + ph), _INK, 1)
    su, sv = r.frame.size_mm
    step = _tick(max(su, sv))
    for t in np.arange(0.0, su + 1e-9, step):
        x = int(round(_LEFT + t * k))
        cv2.line(img, (x, _TOP + ph), (x, _TOP + ph + 5), _INK, 1)
        cv2.putText(img, f"{t:g}", (x - 8, _TOP + ph + 18), _FONT, 0.4, _INK, 1, cv2.LINE_AA)
    for t in np.arange(0.0, sv + 1e-9, step):
        y = int(round(_TOP + ph - t * k))
        cv2.line(img, (_LEFT - 5, y), (_LEFT, y), _INK, 1)
        cv2.putText(img, f"{t:g}", (6, y + 4), _FONT, 0.4, _INK, 1, cv2.LINE_AA)
    cv2.putText(img, "u, mm", (_LEFT + pw - 40, _TOP + ph + 34), _FONT, 0.4, _INK, 1,
                cv2.LINE_AA)
    cv2.putText(img, "v, mm", (6, _TOP - 6), _FONT, 0.4, _INK, 1, cv2.LINE_AA)
    for i, (text, colour) in enumerate(reading_lines(r)):
        cv2.putText(img, text, (_LEFT, 18 + 19 * i), _FONT, 0.5, colour, 1, cv2.LINE_AA)
    return img


def readback_picture(readings: list[MarkReading]) -> np.ndarray:
    """The panels of ``readings`` side by side (at least one), BGR uint8."""
    panels = [reading_panel(r) for r in readings]
    h = max(p.shape[0] for p in panels)
    return np.hstack([cv2.copyMakeBorder(p, 0, h - p.shape[0], 0, 0, cv2.BORDER_CONSTANT,
                                         value=(255, 255, 255)) for p in panels])
