"""A pattern placed on the part: where and how it is marked — the core placed-pattern type
of the commands, the GUI and the project files."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from insitu.errors import FormatError
from insitu.geometry.pose import flat_pose
from insitu.marking.modes import projection_mode
from insitu.patterns import Pattern, hatch, load_pattern, order_paths
from insitu.patterns.vector import BEAM_MM


@dataclass(frozen=True)
class Placement:
    """Where and how a pattern is marked. ``pattern``: a file or a ``text:``/``qr:`` spec;
    ``at_mm``: its centre, world x, y; ``width_mm``: its width before rotating (a code's
    without its quiet zone; None: the size it loads at); ``rotate_deg``: CCW about +z;
    ``mode``: a key of ``marking.PROJECTIONS``; ``hatch_mm``: fill spacing (None: outlines
    only — but a code is hatched along its modules); ``hatch_angle_deg``, ``cross``: the
    hatch's direction(s); ``fill``: a DXF's closed outlines, auto|all|none; ``beam_mm``: the
    beam's width (strokes at least this wide, once placed, are marked as areas); ``pen``:
    the name of its pen (:mod:`insitu.formats.pens`; None: the table's default); ``paint``:
    how an SVG's shaded paints are marked, threshold|dither."""

    pattern: str
    at_mm: tuple[float, float]
    width_mm: float
    rotate_deg: float = 0.0
    mode: str = "planar"
    hatch_mm: float | None = None
    hatch_angle_deg: float = 0.0
    cross: bool = False
    fill: str = "auto"
    beam_mm: float = BEAM_MM
    pen: str | None = None
    paint: str = "threshold"

    def in_world(self, T_world_part: np.ndarray) -> Placement:
        """This placement, given in a part's frame, moved where the part lies:
        ``T_world_part`` (4, 4) maps part points (mm) into the world. The centre is mapped,
        the rotation and the hatch direction turn by the pose's angle about +z (a part lies
        flat on the table: its pose is x, y and a turn about z)."""
        T = np.asarray(T_world_part, float)
        x, y = (T[:2, :2] @ np.asarray(self.at_mm, float)) + T[:2, 3]
        turn = flat_pose(T)[2]
        return replace(self, at_mm=(float(x), float(y)), rotate_deg=self.rotate_deg + turn,
                       hatch_angle_deg=self.hatch_angle_deg + turn)

    def placed(self) -> Pattern:
        """The pattern loaded and moved to its place, world mm (FormatError if it cannot be).
        When the scaling decides otherwise for a stroke (wider or thinner than the beam once
        placed), the file is loaded again with the beam in its own size."""
        projection_mode(self.mode)
        p = load_pattern(self.pattern, fill=self.fill, beam=self.beam_mm, paint=self.paint)
        width = p.mark_width if self.width_mm is None else self.width_mm
        scale = width / p.mark_width if p.mark_width > 0 else 1.0
        if (p.beam_mm is not None and any((w >= p.beam_mm) != (w * scale >= self.beam_mm)
                                          for w in p.stroke_widths)) \
                or (p.raster_mm is not None and p.raster_mm * scale > 1.01 * self.beam_mm):
            p = load_pattern(self.pattern, fill=self.fill, beam=self.beam_mm / scale,
                             paint=self.paint)
            width = p.mark_width if self.width_mm is None else self.width_mm
        return p.placed(self.at_mm, width, self.rotate_deg)

    def code_hatch(self, pattern: Pattern) -> tuple[float, float]:
        """(spacing mm, angle °) of a placed code's default hatch: along its module rows, a
        whole number of lines per module, no further apart than the beam."""
        f = pattern.frame
        module = float(np.linalg.norm(f[1] - f[0])) / (pattern.code.cols
                                                       + 2 * pattern.code.quiet)
        return module / math.ceil(module / self.beam_mm - 1e-9), self.rotate_deg

    def polylines(self, pattern: Pattern) -> list[np.ndarray]:
        """What to mark of the placed ``pattern``, in marking order: hatched fill and outlines
        with ``hatch_mm`` (a code's hatch lines joined back and forth where they end along a
        module edge: :func:`~insitu.patterns.fill.joined`), else the outlines and open
        paths. (N, 2) world mm each."""
        code = pattern.code is not None      # a code's lines joined along its module edges
        if self.hatch_mm is not None:
            return hatch(pattern, self.hatch_mm, self.hatch_angle_deg, self.cross,
                         start=self.at_mm, join=code)
        if code and pattern.frame is not None:
            spacing, angle = self.code_hatch(pattern)
            return hatch(pattern, spacing, angle, self.cross, start=self.at_mm, join=True)
        if pattern.is_empty:
            raise FormatError(f"pattern {pattern.name}: empty (nothing to mark)")
        loops = [np.vstack([c, c[:1]]) for c in pattern.contours]
        return order_paths(loops + list(pattern.paths), start=self.at_mm)
