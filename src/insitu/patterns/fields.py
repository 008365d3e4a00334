"""Variable data in a spec's text: ``text:"SN {serial:05d} {date:%Y-%m-%d}"``,
``qr:"{serial}"``, ``datamatrix:"(01){gtin}(21){serial}"``.

Fields, in braces (Python's format syntax; ``{{`` and ``}}`` are literal braces):

    {serial}, {serial:05d}   the part's serial number (an int; any int format spec)
    {date}, {date:%d.%m.%Y}  the local date of planning (strftime; default %Y-%m-%d)
    {time}, {time:%H%M}      the local time of planning (strftime; default %H:%M)
    {NAME}, {NAME:>8}        a field the user gives (``--var NAME=VALUE``; str format spec)

Only the text of a spec source that encodes or writes text is a template (text:, qr:,
datamatrix:, microqr:, code128:); a file or ``fiducials:`` is never rendered. A spec without
braces renders to itself. Every failure is a one-line FormatError naming the field.
"""

from __future__ import annotations

import re
import string
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime

from insitu.errors import FormatError
from insitu.patterns.load import spec_parts

BUILTIN = ("serial", "date", "time")
TEMPLATE_PREFIXES = ("text:", "qr:", "datamatrix:", "microqr:", "code128:")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class Variables:
    """What the fields render to: ``serial`` (None: no serial issued — a template using it is
    refused), the user's ``fields`` (name → text) and ``time``, the local time of planning."""

    serial: int | None = None
    fields: Mapping[str, str] = field(default_factory=dict)
    time: datetime = field(default_factory=lambda: datetime.now().astimezone())


def _template(spec: str) -> tuple[str, str, str] | None:
    """(prefix, text, options) of a spec whose text is a template; None otherwise."""
    parts = spec_parts(spec)
    return parts if parts is not None and parts[0] in TEMPLATE_PREFIXES else None


def _parse(text: str, where: str) -> list[tuple[str, str | None, str]]:
    """[(literal, field name or None, format spec)] of a template; FormatError when malformed."""
    try:
        items = list(string.Formatter().parse(text))
    except ValueError as e:
        raise FormatError(f"{where}: {e} (write {{{{ and }}}} for literal braces)") from None
    out = []
    for literal, name, spec, conv in items:
        if name is not None:
            shown = "{" + name + (f"!{conv}" if conv else "") + (f":{spec}" if spec else "") + "}"
            if not _NAME.fullmatch(name):
                raise FormatError(f"{where}: field {shown}: expected a name such as {{serial}}, "
                                  f"{{date:%Y-%m-%d}} or {{gtin}} ({{{{ for a literal brace)")
            if conv or "{" in (spec or ""):
                raise FormatError(f"{where}: field {shown}: conversions and nested fields are "
                                  "not supported")
        out.append((literal, name, spec or ""))
    return out


def is_template(spec: str) -> bool:
    """The spec's text may hold fields (it has a brace); never raises, even when malformed."""
    parts = _template(spec)
    return parts is not None and bool(re.search(r"[{}]", parts[1]))


def template_fields(spec: str) -> tuple[str, ...]:
    """The field names a spec's text uses, in order, each once (() for a file or a text
    without fields)."""
    parts = _template(spec)
    if parts is None or not re.search(r"[{}]", parts[1]):
        return ()
    names = [n for _, n, _ in _parse(parts[1], f"{parts[0]}{parts[1][:40]!r}") if n is not None]
    return tuple(dict.fromkeys(names))


def uses_serial(spec: str) -> bool:
    """The spec's text holds ``{serial}``."""
    return "serial" in template_fields(spec)


def render_text(text: str, values: Variables, where: str = "pattern") -> str:
    """``text`` with its fields replaced by ``values``; FormatError naming a field that has
    no value or whose format spec does not fit it."""
    out = []
    for literal, name, spec in _parse(text, where):
        out.append(literal)
        if name is None:
            continue
        shown = "{" + name + (f":{spec}" if spec else "") + "}"
        if name == "serial":
            if values.serial is None:
                raise FormatError(f"{where}: field {shown} needs a serial number (plan it into a "
                                  "job: insitu mark ... -o JOB, with a counter)")
            value, kind = values.serial, "a serial number (an int, e.g. {serial:05d})"
            if spec[-1:].isalpha() and spec[-1] not in "bdnoxX":
                raise FormatError(f"{where}: field {shown}: format spec {spec!r} does not fit "
                                  f"{kind}")
        elif name in ("date", "time"):
            fmt = spec or ("%Y-%m-%d" if name == "date" else "%H:%M")
            out.append(values.time.strftime(fmt))
            continue
        elif name in values.fields:
            value, kind = values.fields[name], "a text field (e.g. {NAME:>8})"
        else:
            raise FormatError(f"{where}: field {shown} has no value (give it a "
                              f"value: {name}=VALUE)")
        try:
            out.append(format(value, spec))
        except (ValueError, TypeError):
            raise FormatError(f"{where}: field {shown}: format spec {spec!r} does not fit "
                              f"{kind}") from None
    return "".join(out)


def render_spec(spec: str, values: Variables) -> str:
    """The spec with its text rendered (quoted, its options kept); a file, ``fiducials:`` or a
    text without braces is returned as it is."""
    parts = _template(spec)
    if parts is None or not re.search(r"[{}]", parts[1]):
        return spec
    prefix, text, opts = parts
    return f'{prefix}"{render_text(text, values, f"{prefix}{text[:40]!r}")}"{opts}'


def parse_fields(items: list[str] | tuple[str, ...]) -> dict[str, str]:
    """``NAME=VALUE`` items (``--var``) → {name: value}; FormatError for a malformed item, a
    built-in name (serial, date, time) or a name given twice."""
    out: dict[str, str] = {}
    for item in items:
        name, eq, value = item.partition("=")
        name = name.strip()
        if not eq or not _NAME.fullmatch(name):
            raise FormatError(f"var {item!r}: expected NAME=VALUE, e.g. gtin=09506000134352",
                              field="var")
        if name in BUILTIN:
            raise FormatError(f"var {name}: {{{name}}} is built in (serial from the counter, "
                              "date and time of planning)", field="var")
        if name in out:
            raise FormatError(f"var {name}: given twice", field="var")
        out[name] = value
    return out
