"""A calibration's verdict: its headline figures against their limits — pass, check (usable:
look at its picture, record again when in doubt) or fail (record again) — with each figure
named in words, the others (counts, the fit's details) listed after them. The limits: a
camera's reprojection RMS of 0.5 px is good practice (OpenCV's checkerboard calibrations
reach 0.1–0.3 px), 1 px is a poor one; heights and landing spots are held to the marking's
tolerance (docs/accuracy.md: height calibrations 0.02 mm RMS, field corrections 0.013 mm
RMS; Mikkelstrup et al.'s 0.071 mm)."""

from __future__ import annotations

import math
from dataclasses import dataclass

LEVELS = ("pass", "check", "fail")


@dataclass(frozen=True)
class Limit:
    """``key`` of the residuals, said as ``label`` in ``unit``; above ``check_above`` the
    verdict is check, above ``fail_above`` fail."""

    key: str
    label: str
    unit: str
    check_above: float
    fail_above: float

    def level(self, value: float) -> str:
        if not math.isfinite(value) or value > self.fail_above:
            return "fail"
        return "check" if value > self.check_above else "pass"


LIMITS: dict[str, tuple[Limit, ...]] = {
    "camera": (Limit("rms_px", "reprojection error, RMS", "px", 0.5, 1.0),
               Limit("max_view_rms_px", "worst view's reprojection error, RMS", "px", 1.0,
                     2.0)),
    "height": (Limit("sheet_cv_rms_mm", "height error on planes left out of the fit, RMS",
                     "mm", 0.05, 0.1),
               Limit("sheet_rms_mm", "height error of the fit, RMS", "mm", 0.05, 0.1)),
    "field": (Limit("cv_rms_mm", "landing error after correction, spots left out, RMS", "mm",
                    0.05, 0.1),
              Limit("cv_max_mm", "landing error after correction, spots left out, max", "mm",
                    0.15, 0.3)),
}


@dataclass(frozen=True)
class Row:
    """One line of the page's table: ``name`` in words, ``value`` as text, ``limit`` (""
    when none) and ``level`` (a :data:`LEVELS` entry; "" for a figure without a limit)."""

    name: str
    value: str
    limit: str
    level: str


def figure(value: float, unit: str = "") -> str:
    """A residual as text: counts whole, others to 4 significant digits."""
    if not unit and math.isfinite(value) and abs(value) >= 1 and value == int(value):
        return f"{int(value):,}"
    return f"{value:.4g}" + (f" {unit}" if unit else "")


def verdict(kind: str, residuals: dict[str, float]) -> tuple[str, str, list[Row]]:
    """(level, one line saying it, the table's rows) for a ``kind`` calibration's
    ``residuals``: the worst of its limited figures; "check" when none of them is there."""
    rows, levels, worst = [], [], None
    for lim in LIMITS.get(kind, ()):
        if lim.key not in residuals:
            continue
        v = float(residuals[lim.key])
        level = lim.level(v)
        rows.append(Row(lim.label, figure(v, lim.unit),
                        f"pass ≤ {lim.check_above:g}, fail > {lim.fail_above:g} {lim.unit}",
                        level))
        levels.append(level)
        if worst is None or LEVELS.index(level) > LEVELS.index(worst[0]):
            worst = (level, lim, v)
    limited = {lim.key for lim in LIMITS.get(kind, ())}
    rows += [Row(k.replace("_", " "), figure(float(v)), "", "")
             for k, v in residuals.items() if k not in limited]
    if worst is None:
        return "check", f"{kind} calibration: no figure to judge it by: check its picture", rows
    level, lim, v = worst
    what = {"pass": "pass", "check": "check its picture (usable, record again when in doubt)",
            "fail": "fail: record it again"}[level]
    return level, (f"{kind} calibration: {what} — {lim.label} {figure(v, lim.unit)} "
                   f"(pass ≤ {lim.check_above:g} {lim.unit})"), rows
