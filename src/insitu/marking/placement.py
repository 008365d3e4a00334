"""A pattern placed on the part: where and how it is marked — the core placed-pattern type
of the commands, the GUI and the project files."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from insitu.errors import FormatError
from insitu.marking.modes import projection_mode
from insitu.patterns import Pattern, hatch, load_pattern, order_paths


@dataclass(frozen=True)
class Placement:
    """Where and how a pattern is marked. ``pattern``: a file or a ``text:``/``qr:`` spec;
    ``at_mm``: its centre, world x, y; ``width_mm``: its width before rotating;
    ``rotate_deg``: CCW about +z; ``mode``: a key of ``marking.PROJECTIONS``; ``hatch_mm``:
    fill spacing (None: outlines only); ``hatch_angle_deg``, ``cross``: the hatch's
    direction(s)."""

    pattern: str
    at_mm: tuple[float, float]
    width_mm: float
    rotate_deg: float = 0.0
    mode: str = "planar"
    hatch_mm: float | None = None
    hatch_angle_deg: float = 0.0
    cross: bool = False

    def placed(self) -> Pattern:
        """The pattern loaded and moved to its place, world mm (FormatError if it cannot be)."""
        projection_mode(self.mode)
        return load_pattern(self.pattern).placed(self.at_mm, self.width_mm, self.rotate_deg)

    def polylines(self, pattern: Pattern) -> list[np.ndarray]:
        """What to mark of the placed ``pattern``, in marking order: hatched fill and outlines
        with ``hatch_mm``, else the outlines and open paths. (N, 2) world mm each."""
        if self.hatch_mm is not None:
            return hatch(pattern, self.hatch_mm, self.hatch_angle_deg, self.cross,
                         start=self.at_mm)
        if pattern.is_empty:
            raise FormatError(f"pattern {pattern.name}: empty (nothing to mark)")
        loops = [np.vstack([c, c[:1]]) for c in pattern.contours]
        return order_paths(loops + list(pattern.paths), start=self.at_mm)
