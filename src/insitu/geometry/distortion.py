"""Scan-field distortions: where the beam lands on z = 0 minus where it was commanded.

A distortion is any callable ``(N, 2) commands, mm → (N, 2) shifts, mm``. The simulated head
uses :class:`PolynomialFieldDistortion` (pincushion/barrel, scale, rotation, keystone and
smooth higher-order terms, as an uncorrected galvo field shows).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


class FieldDistortion(Protocol):
    def __call__(self, cmd_xy: np.ndarray) -> np.ndarray: ...


@dataclass(frozen=True)
class NoDistortion:
    def __call__(self, cmd_xy: np.ndarray) -> np.ndarray:
        return np.zeros_like(np.asarray(cmd_xy, dtype=np.float64))


def _monomials(xy: np.ndarray, scale: float, degree: int) -> np.ndarray:
    """(N, 2) → (N, M) monomials (x/s)^i (y/s)^j with i + j <= degree, M = (d+1)(d+2)/2."""
    x, y = xy[:, 0] / scale, xy[:, 1] / scale
    return np.column_stack([x**i * y ** (k - i) for k in range(degree + 1) for i in range(k + 1)])


@dataclass(frozen=True)
class PolynomialFieldDistortion:
    """Shift = polynomial in (x/scale, y/scale). ``coeffs``: (M, 2) mm, monomial order of
    :func:`_monomials`; ``degree`` fixes M."""

    coeffs: tuple[tuple[float, float], ...]
    degree: int = 3
    scale_mm: float = 100.0

    def __call__(self, cmd_xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(cmd_xy, dtype=np.float64).reshape(-1, 2)
        return _monomials(xy, self.scale_mm, self.degree) @ np.asarray(self.coeffs)

    def to_dict(self) -> dict:
        return {"type": "polynomial", "degree": self.degree, "scale_mm": self.scale_mm,
                "coeffs_mm": [list(c) for c in self.coeffs]}

    @classmethod
    def from_dict(cls, d: dict) -> "PolynomialFieldDistortion":
        return cls(tuple(tuple(map(float, c)) for c in d["coeffs_mm"]), int(d["degree"]),
                   float(d["scale_mm"]))

    @classmethod
    def random(cls, rng: np.random.Generator, rms_mm: float = 0.8, half_field_mm: float = 90.0,
               degree: int = 3) -> "PolynomialFieldDistortion":
        """A smooth random field whose RMS over the square ±half_field is ``rms_mm``.

        Built as a galvo field looks uncorrected: pincushion (r² x, r² y), a scale and
        rotation error, keystone from the mirror separation, plus random terms that decay
        with order. No constant offset (the head's zero is aligned).
        """
        m = (degree + 1) * (degree + 2) // 2
        orders = np.array([k for k in range(degree + 1) for _ in range(k + 1)])
        coeffs = rng.normal(size=(m, 2)) * (0.35 ** orders)[:, None]
        coeffs[0] = 0.0
        base = cls(tuple(map(tuple, coeffs)), degree, half_field_mm)
        # Pincushion: δ = p · r² (x, y), expressed in monomials of degree 3.
        grid = np.stack(np.meshgrid(*[np.linspace(-half_field_mm, half_field_mm, 41)] * 2), -1)
        grid = grid.reshape(-1, 2)
        r2 = ((grid / half_field_mm) ** 2).sum(1, keepdims=True)
        pin = rng.uniform(0.8, 1.2) * r2 * grid / half_field_mm
        total = base(grid) + pin
        A = _monomials(grid, half_field_mm, degree)
        fitted, *_ = np.linalg.lstsq(A, total, rcond=None)
        rms = np.sqrt(np.mean(np.sum((A @ fitted) ** 2, axis=1)))
        return cls(tuple(map(tuple, fitted * (rms_mm / rms))), degree, half_field_mm)


def distortion_from_dict(d: dict | None) -> FieldDistortion:
    """Rebuild a distortion written by ``to_dict`` (None or type "none": no distortion)."""
    if not d or d.get("type") == "none":
        return NoDistortion()
    if d["type"] == "polynomial":
        return PolynomialFieldDistortion.from_dict(d)
    raise ValueError(f"unknown field distortion type {d['type']!r}")
