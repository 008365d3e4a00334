"""``load_pattern(spec)``: the CLI's ``--pattern`` argument → :class:`Pattern`.

Specs (cli.md: SVG, DXF, PNG, text:"...", qr:"..."), each with optional ``;key=value``
options at the end::

    logo.svg                         SVG (fills → contours, strokes → paths)
    part.dxf                         DXF (closed outlines → contours, open ones → paths)
    photo.png;mode=dither;width=20   image: mode fill|threshold|dither, dpi, width (mm),
                                     threshold (0–1), invert (0/1); also .jpg .bmp .tif
    text:"Serial 0042";font=DejaVu Serif Bold;size=5
                                     glyph outlines; font family or .ttf path, size = em in mm
    qr:"https://example.com";ec=H;quiet=2;invert=1
                                     QR code: error correction L|M|Q|H (M), quiet zone in
                                     modules (4), module size mm (module=1)
    fiducials:5x7;pitch=5;diameter=1;filled=0
                                     calibration grid of circles

Quotes around the text or data are optional (the shell usually strips them); quote it when it
contains ``;key=``. Keyword arguments give defaults for the same keys; the spec's own options
win. Every failure is a one-line FormatError.
"""

from __future__ import annotations

import re
from pathlib import Path

from insitu.errors import FormatError
from insitu.patterns.model import Pattern

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")
_KEYS = {
    "text": {"font": str, "size": float, "line_spacing": float},
    "qr": {"ec": str, "quiet": int, "invert": bool, "module": float},
    "fiducials": {"pitch": float, "diameter": float, "filled": bool},
    "image": {"mode": str, "dpi": float, "width": float, "threshold": float, "invert": bool},
    "svg": {}, "dxf": {},
}
_OPTS = r"(?P<opts>(?:;[A-Za-z_]+=[^;]*)*)"
_GENERATED = re.compile(r"^(?P<kind>text|qr|fiducials):(?P<rest>.*)$", re.S)


def _value(kind: str, key: str, raw, where: str):
    typ = _KEYS[kind].get(key)
    if typ is None:
        allowed = ", ".join(_KEYS[kind]) or "none"
        raise FormatError(f"{where}: unknown option {key!r} (allowed: {allowed})")
    if not isinstance(raw, str):
        return raw
    raw = raw.strip()
    try:
        if typ is bool:
            if raw.lower() not in ("1", "0", "true", "false", "yes", "no", ""):
                raise ValueError(raw)
            return raw.lower() in ("1", "true", "yes", "")
        return typ(raw)
    except ValueError:
        raise FormatError(f"{where}: option {key}={raw!r} is not a {typ.__name__}") from None


def _options(kind: str, opts: str, defaults: dict, where: str) -> dict:
    known = set().union(*_KEYS.values())
    bad = set(defaults) - known
    if bad:
        raise FormatError(f"load_pattern: unknown option {sorted(bad)[0]!r}")
    out = {k: _value(kind, k, v, where) for k, v in defaults.items() if k in _KEYS[kind]}
    for item in filter(None, opts.split(";")):
        key, _, raw = item.partition("=")
        out[key.strip()] = _value(kind, key.strip(), raw, where)
    return out


def _split_generated(rest: str) -> tuple[str, str]:
    """(payload without quotes, options string) of what follows ``kind:``."""
    for q in ('"', "'"):
        if rest.startswith(q):
            m = re.match(rf"^{q}(?P<body>.*){q}{_OPTS}$", rest, re.S)
            if m:
                return m["body"], m["opts"]
    m = re.match(rf"^(?P<body>.*?){_OPTS}$", rest, re.S)
    return m["body"], m["opts"]


def _generated(kind: str, rest: str, defaults: dict) -> Pattern:
    from insitu.patterns import codes, text

    body, opts = _split_generated(rest)
    where = f"{kind}:{body[:40]!r}"
    o = _options(kind, opts, defaults, where)
    if kind == "text":
        return text.text_pattern(body, font=o.get("font", text.DEFAULT_FONT),
                                 size_mm=o.get("size", 10.0),
                                 line_spacing=o.get("line_spacing", 1.0))
    if kind == "qr":
        return codes.qr_pattern(body, error=o.get("ec", "M"), quiet_zone=o.get("quiet", 4),
                                module_mm=o.get("module", 1.0), invert=o.get("invert", False))
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", body)
    if not m:
        raise FormatError(f"{where}: expected fiducials:ROWSxCOLS, e.g. fiducials:5x5")
    return codes.fiducial_grid(int(m[1]), int(m[2]), pitch_mm=o.get("pitch", 5.0),
                               diameter_mm=o.get("diameter", 1.0),
                               filled=o.get("filled", True))


def _file(spec: str, defaults: dict) -> Pattern:
    from insitu.patterns import raster, vector

    if any(ord(c) < 32 for c in spec):
        raise FormatError(f"--pattern {spec!r}: no such pattern file")
    path, opts = Path(spec), ""
    if not path.is_file():
        m = re.match(rf"^(?P<file>.*?){_OPTS}$", spec, re.S)
        if m and m["opts"]:
            path, opts = Path(m["file"]), m["opts"]
    suffix = path.suffix.lower()
    kind = ("svg" if suffix == ".svg" else "dxf" if suffix == ".dxf"
            else "image" if suffix in IMAGE_SUFFIXES else None)
    if kind is None:
        if not path.exists():
            raise FormatError(f"{path}: no such pattern file (or give text:\"...\" or "
                              f"qr:\"...\")")
        raise FormatError(f"{path}: unknown pattern type {suffix or '(no suffix)'} "
                          f"(expected .svg, .dxf, {', '.join(IMAGE_SUFFIXES)})")
    o = _options(kind, opts, defaults, str(path))
    if kind == "svg":
        return vector.load_svg(path)
    if kind == "dxf":
        return vector.load_dxf(path)
    return raster.load_image(path, dpi=o.get("dpi"), width_mm=o.get("width"),
                             mode=o.get("mode", "fill"), threshold=o.get("threshold", 0.5),
                             invert=o.get("invert", False))


def load_pattern(spec: str | Path, **defaults) -> Pattern:
    """A pattern from a file path (.svg, .dxf, image) or a ``text:``/``qr:``/``fiducials:``
    spec (see the module docstring). Raises FormatError with a one-line message."""
    spec_s = str(spec)
    if not spec_s.strip():
        raise FormatError("--pattern: empty (give a file, text:\"...\" or qr:\"...\")")
    m = _GENERATED.match(spec_s) if not isinstance(spec, Path) else None
    if m and not Path(spec_s).is_file():
        return _generated(m["kind"], m["rest"], defaults)
    return _file(spec_s, defaults)
