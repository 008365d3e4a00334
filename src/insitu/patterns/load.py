"""``load_pattern(spec)``: the CLI's ``--pattern`` argument → :class:`Pattern`, by the one table
of pattern sources, :data:`SOURCES` (the CLI's help, the GUI's file dialog and drag and drop,
and the project files read it). A new source is a module with its loader and one entry here.

A spec is a file (its suffix picks the source) or ``prefix:payload`` (text:, qr:, datamatrix:,
microqr:, code128:, fiducials:),
each with optional ``;key=value`` options at the end (the entry's ``options``)::

    logo.svg                         SVG or .svgz (fills → contours, strokes → paths),
                                     paint=threshold|dither for gradients and the like
    photo.png;mode=dither;width=20   image: mode fill|threshold|dither, dpi, width (mm),
                                     threshold (0–1), invert (0/1)
    text:"Serial 0042";font=DejaVu Serif Bold;size=5
                                     glyph outlines; font family or .ttf path, size = em in mm
    qr:"https://example.com";ec=H;quiet=2;invert=1
                                     QR code: error correction L|M|Q|H (M), quiet zone in
                                     modules (4), module size mm (module=1)
    datamatrix:"(01)09501101530003(21)0042";module=0.3
                                     Data Matrix ECC 200 (GS1 when the data starts with an
                                     AI in brackets; gs1=0/1 to say), quiet zone 2, square=1
    microqr:"12345";ec=M             Micro QR (quiet zone 2)
    code128:"SN-0042";aspect=0.25    Code 128 (quiet zone 10, bars aspect × width tall)
    fiducials:5x7;pitch=5;diameter=1;filled=0
                                     calibration grid of circles

Quotes around the text or data are optional (the shell usually strips them); quote it when it
contains ``;key=``. Keyword arguments give defaults for the same keys; the spec's own options
win. Every failure is a one-line FormatError.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from insitu.errors import FormatError
from insitu.patterns.model import Pattern
from insitu.patterns.vector import BEAM_MM


@dataclass(frozen=True)
class PatternSource:
    """One way to make a pattern. ``load(payload, options)`` → :class:`Pattern`: ``payload``
    is the file's Path (a file source, picked by its ``suffixes``) or the text after
    ``prefix`` (a spec source, e.g. ``qr:``); ``options``: the ``;key=value`` options parsed
    to their types (``option_types``: key → type). ``description``: one line (CLI help);
    ``payload_hint``: how a spec source's payload is written."""

    load: Callable[[Any, dict], Pattern]
    description: str
    option_types: dict[str, type] = field(default_factory=dict)
    suffixes: tuple[str, ...] = ()
    prefix: str | None = None
    payload_hint: str = '"..."'

    @property
    def usage(self) -> str:
        """How it is written: its suffixes, or prefix and payload."""
        return " ".join(self.suffixes) if self.prefix is None else self.prefix + self.payload_hint


def _module(name: str):
    """A source's module, imported when a pattern of that source is first loaded."""
    return importlib.import_module(f"insitu.patterns.{name}")


def _image(path: Path, o: dict) -> Pattern:
    return _module("raster").load_image(path, dpi=o.get("dpi"), width_mm=o.get("width"),
                             mode=o.get("mode", "fill"), threshold=o.get("threshold", 0.5),
                             invert=o.get("invert", False))


def _text(body: str, o: dict) -> Pattern:
    text = _module("text")
    return text.text_pattern(body, font=o.get("font", text.DEFAULT_FONT),
                             size_mm=o.get("size", 10.0), line_spacing=o.get("line_spacing", 1.0))


def _qr(body: str, o: dict) -> Pattern:
    return _module("codes").qr_pattern(body, error=o.get("ec", "M"),
                                       quiet_zone=o.get("quiet", 4),
                                       module_mm=o.get("module", 1.0),
                                       invert=o.get("invert", False))


def _zxing(symbology: str):
    def load(body: str, o: dict) -> Pattern:
        opts = {k: o[k] for k in ("ec", "square", "aspect") if k in o}
        if symbology == "datamatrix":
            opts["gs1"] = o.get("gs1", body.startswith("("))
            if opts["gs1"]:
                _module("gs1").check_gtin(body, f"datamatrix:{body[:40]!r}")
        return _module("codes").code_pattern(symbology, body, module_mm=o.get("module", 1.0),
                                             quiet_zone=o.get("quiet"), **opts)
    return load


def _fiducials(body: str, o: dict) -> Pattern:
    m = re.fullmatch(r"\s*(\d+)\s*[xX×]\s*(\d+)\s*", body)
    if not m:
        raise FormatError(f"fiducials:{body[:40]!r}: expected fiducials:ROWSxCOLS, e.g. "
                          "fiducials:5x5")
    return _module("codes").fiducial_grid(int(m[1]), int(m[2]), pitch_mm=o.get("pitch", 5.0),
                                          diameter_mm=o.get("diameter", 1.0),
                                          filled=o.get("filled", True))


SOURCES: dict[str, PatternSource] = {
    "svg": PatternSource(lambda path, o: _module("svg").load_svg(
                             path, beam_mm=o.get("beam", BEAM_MM),
                             paint=o.get("paint", "threshold")),
                         "SVG drawing, strokes ≥ ;beam= mm as areas, shaded paints "
                         ";paint=threshold|dither", {"beam": float, "paint": str},
                         suffixes=(".svg", ".svgz")),
    "dxf": PatternSource(lambda path, o: _module("dxf").load_dxf(
                             path, fill=o.get("fill", "auto"), units=o.get("units")),
                         "DXF drawing, ;fill=auto|all|none ;units=", {"fill": str, "units": str},
                         suffixes=(".dxf",)),
    "image": PatternSource(_image, "image, ;mode=fill|threshold|dither",
                           {"mode": str, "dpi": float, "width": float, "threshold": float,
                            "invert": bool},
                           suffixes=(".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")),
    "text": PatternSource(_text, "text outlines, ;font= ;size= mm",
                          {"font": str, "size": float, "line_spacing": float}, prefix="text:"),
    "qr": PatternSource(_qr, "QR code, ;ec=L|M|Q|H",
                        {"ec": str, "quiet": int, "invert": bool, "module": float},
                        prefix="qr:"),
    "datamatrix": PatternSource(_zxing("datamatrix"), "Data Matrix ECC 200, GS1 when it "
                                "starts with (AI), ;square=0 for rectangles",
                                {"quiet": int, "module": float, "gs1": bool, "square": bool},
                                prefix="datamatrix:"),
    "microqr": PatternSource(_zxing("microqr"), "Micro QR code, ;ec=L|M|Q",
                             {"ec": str, "quiet": int, "module": float}, prefix="microqr:"),
    "code128": PatternSource(_zxing("code128"), "Code 128, ;aspect= bar height / width",
                             {"quiet": int, "module": float, "aspect": float},
                             prefix="code128:"),
    "fiducials": PatternSource(_fiducials, "grid of circles, ;pitch= mm",
                               {"pitch": float, "diameter": float, "filled": bool},
                               prefix="fiducials:", payload_hint="ROWSxCOLS"),
}
FILE_SUFFIXES = tuple(x for src in SOURCES.values() for x in src.suffixes)
SPEC_PREFIXES = tuple(src.prefix for src in SOURCES.values() if src.prefix)
_OPTS = r"(?P<opts>(?:;[A-Za-z_]+=[^;]*)*)"


def is_spec(spec: str) -> bool:
    """``spec`` names a spec source (``text:…``), not a file."""
    return spec.startswith(SPEC_PREFIXES)


def sources_help() -> str:
    """Every source, one clause each (the CLI's ``--pattern`` help)."""
    return "; ".join(f"{src.usage} ({src.description})" for src in SOURCES.values())


def _value(kind: str, key: str, raw, where: str):
    typ = SOURCES[kind].option_types.get(key)
    if typ is None:
        allowed = ", ".join(SOURCES[kind].option_types) or "none"
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
    known = set().union(*(src.option_types for src in SOURCES.values()))
    bad = set(defaults) - known
    if bad:
        raise FormatError(f"load_pattern: unknown option {sorted(bad)[0]!r}")
    types = SOURCES[kind].option_types
    out = {k: _value(kind, k, v, where) for k, v in defaults.items() if k in types}
    for item in filter(None, opts.split(";")):
        key, _, raw = item.partition("=")
        out[key.strip()] = _value(kind, key.strip(), raw, where)
    return out


def _split_spec(rest: str) -> tuple[str, str]:
    """(payload without quotes, options string) of what follows ``prefix``."""
    for q in ('"', "'"):
        if rest.startswith(q):
            m = re.match(rf"^{q}(?P<body>.*){q}{_OPTS}$", rest, re.S)
            if m:
                return m["body"], m["opts"]
    m = re.match(rf"^(?P<body>.*?){_OPTS}$", rest, re.S)
    return m["body"], m["opts"]


def spec_parts(spec: str) -> tuple[str, str, str] | None:
    """(prefix, payload without quotes, options string) of a spec source's spec, e.g.
    ``('qr:', 'SN 1', ';ec=H')``; None for a file."""
    kind = next((k for k, src in SOURCES.items() if src.prefix and spec.startswith(src.prefix)),
                None)
    if kind is None or Path(spec).is_file():
        return None
    prefix = SOURCES[kind].prefix
    return (prefix, *_split_spec(spec[len(prefix):]))


def _spec(kind: str, rest: str, defaults: dict) -> Pattern:
    body, opts = _split_spec(rest)
    src = SOURCES[kind]
    return src.load(body, _options(kind, opts, defaults, f"{src.prefix}{body[:40]!r}"))


def _file(spec: str, defaults: dict) -> Pattern:
    if any(ord(c) < 32 for c in spec):
        raise FormatError(f"pattern {spec!r}: no such pattern file", field="pattern")
    path, opts = Path(spec), ""
    if not path.is_file():
        m = re.match(rf"^(?P<file>.*?){_OPTS}$", spec, re.S)
        if m and m["opts"]:
            path, opts = Path(m["file"]), m["opts"]
    suffix = path.suffix.lower()
    kind = next((k for k, src in SOURCES.items() if suffix in src.suffixes), None)
    if kind is None:
        if not path.exists():
            raise FormatError(f"{path}: no such pattern file (or give text:\"...\" or "
                              f"qr:\"...\")")
        raise FormatError(f"{path}: unknown pattern type {suffix or '(no suffix)'} "
                          f"(expected {', '.join(FILE_SUFFIXES)})")
    return SOURCES[kind].load(path, _options(kind, opts, defaults, str(path)))


def load_pattern(spec: str | Path, **defaults) -> Pattern:
    """A pattern from a file path or a spec of one of :data:`SOURCES` (see the module
    docstring). Raises FormatError with a one-line message."""
    spec_s = str(spec)
    if not spec_s.strip():
        raise FormatError("pattern: empty (give a file, text:\"...\" or qr:\"...\")",
                          field="pattern")
    kind = next((k for k, src in SOURCES.items() if src.prefix and spec_s.startswith(src.prefix)),
                None) if not isinstance(spec, Path) else None
    if kind is not None and not Path(spec_s).is_file():
        return _spec(kind, spec_s[len(SOURCES[kind].prefix):], defaults)
    return _file(spec_s, defaults)
