"""Patterns to mark: one model in mm (:class:`Pattern`), its sources (:data:`SOURCES`: SVG, DXF,
images, text, QR codes, fiducial grids), fills (hatch, offset) and path ordering.

    >>> from insitu.patterns import load_pattern, hatch
    >>> p = load_pattern('qr:"insitu"').placed((0, 0), width_mm=30)
    >>> polylines = hatch(p, spacing_mm=0.04)          # ordered (N, 2) mm arrays
"""

from insitu.patterns.codes import fiducial_centres, fiducial_grid, qr_pattern
from insitu.patterns.fill import hatch, offset
from insitu.patterns.load import (FILE_SUFFIXES, SOURCES, SPEC_PREFIXES, PatternSource, is_spec,
                                 load_pattern, sources_help)
from insitu.patterns.model import Pattern, from_shapely, to_svg
from insitu.patterns.order import jump_length, order_paths, simplify
from insitu.patterns.raster import load_image
from insitu.patterns.text import text_pattern
from insitu.patterns.dxf import load_dxf
from insitu.patterns.svg import load_svg

__all__ = [
    "FILE_SUFFIXES", "SOURCES", "SPEC_PREFIXES", "Pattern", "PatternSource", "is_spec",
    "sources_help", "fiducial_centres", "fiducial_grid", "from_shapely", "hatch", "jump_length",
    "load_dxf", "load_image", "load_pattern", "load_svg", "offset", "order_paths",
    "qr_pattern", "simplify", "text_pattern", "to_svg",
]
