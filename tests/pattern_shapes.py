"""Shapes the pattern tests share: the sample folder, a 10 mm square and the square with a hole."""

from pathlib import Path

import numpy as np

from insitu.patterns import Pattern

SAMPLES = Path(__file__).resolve().parents[1] / "patterns"
SQUARE = Pattern((np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float),), (), "square")


def square_with_hole() -> Pattern:
    """SQUARE with a hole of 2 mm radius at its centre (64 points)."""
    hole = np.column_stack([5 + 2 * np.cos(np.linspace(0, 2 * np.pi, 64, endpoint=False)),
                            5 + 2 * np.sin(np.linspace(0, 2 * np.pi, 64, endpoint=False))])
    return Pattern((SQUARE.contours[0], hole), (), "holed")
