"""How well the field is corrected, area by area (Mikkelstrup et al., Table 1): max and RMS
of the landing error's x, y components and length over the whole field, the paper's nested
squares and the centre / middle / edge rings."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AreaStats:
    """Mikkelstrup Table 1 for one area: points n; max and RMS of |u_x|, |u_y| and |δ|, mm."""

    name: str
    n: int
    max_mm: tuple[float, float, float]
    rms_mm: tuple[float, float, float]


def stats(dev: np.ndarray, name: str = "all") -> AreaStats:
    """Max and RMS of the x, y components and of the length of ``dev`` (N, 2), mm."""
    dev = np.asarray(dev, np.float64).reshape(-1, 2)
    if not len(dev):
        nan = (float("nan"),) * 3
        return AreaStats(name, 0, nan, nan)
    a = np.column_stack([np.abs(dev), np.linalg.norm(dev, axis=1)])
    return AreaStats(name, len(dev), tuple(map(float, a.max(0))),
                     tuple(map(float, np.sqrt(np.mean(a**2, 0)))))


def areas(points: np.ndarray, half_mm: float) -> list[tuple[str, np.ndarray]]:
    """Areas of the field by the Chebyshev radius max(|x|, |y|) of ``points`` (N, 2), as
    boolean masks: all, the paper's nested squares (150/190 and 50/190 of the field) and
    the centre / middle / edge rings (thirds of ``half_mm``)."""
    r = np.abs(np.asarray(points, np.float64)).max(1)
    h, eps = half_mm, 1e-6
    return [(f"all ±{h:g}", r <= h + eps),
            (f"inner ±{h * 75 / 95:.4g}", r <= h * 75 / 95 + eps),
            (f"inner ±{h * 25 / 95:.4g}", r <= h * 25 / 95 + eps),
            (f"centre ≤{h / 3:.3g}", r <= h / 3 + eps),
            (f"middle {h / 3:.3g}–{2 * h / 3:.3g}", (r > h / 3 + eps) & (r <= 2 * h / 3 + eps)),
            (f"edge >{2 * h / 3:.3g}", r > 2 * h / 3 + eps)]


def area_table(points: np.ndarray, dev: np.ndarray, half_mm: float) -> list[AreaStats]:
    """:func:`stats` of ``dev`` (N, 2) over each of :func:`areas` of ``points`` (N, 2)."""
    return [stats(np.asarray(dev)[m], name) for name, m in areas(points, half_mm)]
