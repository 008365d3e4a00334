"""Patterns to mark: one model in mm (:class:`Pattern`), its sources (:data:`SOURCES`: SVG, DXF,
images, text, QR codes, fiducial grids), fills (hatch, offset) and path ordering.

    >>> from insitu.patterns import load_pattern, hatch
    >>> p = load_pattern('qr:"insitu"').placed((0, 0), width_mm=30)
    >>> polylines = hatch(p, spacing_mm=0.04)          # ordered (N, 2) mm arrays

Names are imported from their modules when first used, so a command that reads one kind of
pattern imports only what that needs.
"""

from __future__ import annotations

import importlib

_HOME = {
    "fiducial_centres": "codes", "fiducial_grid": "codes", "qr_pattern": "codes",
    "hatch": "fill", "offset": "fill",
    "FILE_SUFFIXES": "load", "SOURCES": "load", "SPEC_PREFIXES": "load",
    "PatternSource": "load", "is_spec": "load", "load_pattern": "load", "sources_help": "load",
    "Pattern": "model", "from_shapely": "model", "to_svg": "model",
    "jump_length": "order", "order_paths": "order", "simplify": "order",
    "load_image": "raster", "text_pattern": "text", "load_dxf": "dxf", "load_svg": "svg",
}
__all__ = sorted(_HOME)


def __getattr__(name: str):
    if name not in _HOME:
        raise AttributeError(f"module 'insitu.patterns' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"insitu.patterns.{_HOME[name]}"), name)
    globals()[name] = value
    return value
