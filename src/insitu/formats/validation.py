"""Shared validation for the JSON files: reading JSON with one-line errors, pydantic's
ValidationError turned into one line (``file: frames[3].line.start: expected 2 numbers, got
[1.0]``), and the constrained number types the models share."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import AfterValidator, BeforeValidator, Field, ValidationError
from pydantic_core import PydanticCustomError

from insitu.errors import FormatError
from insitu.formats.limits import MAX_JSON_BYTES, read_limited

_MAX_SHOWN = 60


def show(value: Any) -> str:
    """A short, readable rendering of an input value for an error message."""
    if isinstance(value, str):
        text = repr(value)
    else:
        try:
            text = json.dumps(value, default=repr)
        except (TypeError, ValueError, RecursionError):
            text = repr(value)
    return text if len(text) <= _MAX_SHOWN else text[: _MAX_SHOWN - 3] + "..."


def one_of(names) -> str:
    """``'a', 'b' or 'c'``: the choices of an error message (the keys of a table)."""
    shown = [repr(n) for n in names]
    return shown[0] if len(shown) == 1 else ", ".join(shown[:-1]) + " or " + shown[-1]


def bad(expected: str, got: Any = ..., *, at: str = "", more: int = 0) -> PydanticCustomError:
    """A validation error reading ``<expected>, got <got>``; ``at`` extends the field path
    (e.g. ``frames[3].line`` from a model validator), ``more`` counts further problems."""
    msg = expected if got is ... else f"{expected}, got {show(got)}"
    return PydanticCustomError("insitu", "{message}", {"message": msg, "at": at, "more": more})


def unique_names(items, kind: str, field: str) -> set[str]:
    """The ``name`` of every item of ``items`` (from the list ``field``); a validation error
    at the first name given twice ("pen 'fine' is defined twice" at ``pens[2].name``)."""
    seen: set[str] = set()
    for i, item in enumerate(items):
        if item.name in seen:
            raise bad(f"{kind} {item.name!r} is defined twice", at=f"{field}[{i}].name")
        seen.add(item.name)
    return seen


def loc_text(loc: tuple | list) -> str:
    """('frames', 3, 'line', 'start') → 'frames[3].line.start'."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


def _join(prefix: str, tail: str) -> str:
    if not prefix or not tail or tail.startswith("["):
        return prefix + tail
    return f"{prefix}.{tail}"


_EXPECTED = {
    "float_type": "expected a number", "float_parsing": "expected a number",
    "int_type": "expected an integer", "int_parsing": "expected an integer",
    "int_from_float": "expected an integer", "finite_number": "expected a finite number",
    "string_type": "expected a string", "bool_type": "expected true or false",
    "bool_parsing": "expected true or false", "list_type": "expected a list",
    "tuple_type": "expected a list", "dict_type": "expected an object",
    "model_type": "expected an object", "model_attributes_type": "expected an object",
    "none_required": "expected null",
}


def describe(err: dict, prefix: str = "") -> str:
    """One pydantic error (an item of ``ValidationError.errors()``) as ``path: what``."""
    typ, ctx, inp = err["type"], err.get("ctx") or {}, err.get("input")
    path = _join(_join(prefix, loc_text(err["loc"])), str(ctx.get("at", "")))
    if typ == "insitu":
        what = err["msg"]
    elif typ == "missing":
        what = "missing (required)"
    elif typ == "extra_forbidden":
        what = "not a known field"
    elif typ in ("value_error", "assertion_error"):
        what = str(ctx.get("error", err["msg"]))
    elif typ == "literal_error":
        what = f"expected {ctx.get('expected')}, got {show(inp)}"
    elif typ in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        op, key = {"greater_than": (">", "gt"), "greater_than_equal": (">=", "ge"),
                   "less_than": ("<", "lt"), "less_than_equal": ("<=", "le")}[typ]
        what = f"expected a number {op} {ctx.get(key)}, got {show(inp)}"
    elif typ in ("too_short", "too_long"):
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        n = lo if typ == "too_short" else hi
        what = f"expected {'at least' if typ == 'too_short' else 'at most'} {n} items, got {show(inp)}"
    elif typ in _EXPECTED:
        what = f"{_EXPECTED[typ]}, got {show(inp)}"
    else:
        msg = err["msg"]
        what = f"{msg[:1].lower()}{msg[1:]}, got {show(inp)}"
    if not path:
        what = what.replace("expected an object", "expected a JSON object", 1)
    return f"{path}: {what}" if path else what


def validation_message(source: str | Path, error: ValidationError, prefix: str = "") -> str:
    """``source: <first error>`` plus ``(and N more)``; ``prefix`` goes before every field path."""
    errors = error.errors(include_url=False)
    if not errors:
        return f"{source}: invalid"
    first = errors[0]
    more = len(errors) - 1 + int((first.get("ctx") or {}).get("more", 0))
    text = f"{source}: {describe(first, prefix)}"
    return f"{text} (and {more} more)" if more else text


def read_json(path: Path, missing: str = "file not found", error: type = FormatError) -> Any:
    """Parse the JSON file ``path``; any failure is ``error`` naming the file (and line). Only
    a regular file of at most ``MAX_JSON_BYTES`` is read (:mod:`insitu.formats.limits`)."""
    raw = read_limited(path, MAX_JSON_BYTES, "JSON file", missing=missing, error=error)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise error(f"{path}: not valid JSON (not UTF-8 text at byte {e.start})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise error(f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    except (ValueError, RecursionError) as e:
        raise error(f"{path}: not valid JSON ({e})") from None


def plain(obj: Any) -> Any:
    """``obj`` with numpy arrays/scalars, tuples, Paths and pydantic models made JSON-able."""
    if hasattr(obj, "model_dump"):
        return plain(obj.model_dump(mode="json", exclude_none=True))
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    return obj


# -- shared constrained types (models use ConfigDict(allow_inf_nan=False): floats are finite) --

def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def numbers(*counts: int, what: str = ""):
    """BeforeValidator: a list of ``counts`` (e.g. 2, or 4/5/8) numbers; shape errors only."""
    text = ", ".join(map(str, counts[:-1])) + f" or {counts[-1]}" if len(counts) > 1 else str(counts[0])

    def check(v: Any) -> Any:
        if isinstance(v, np.ndarray):
            v = v.tolist()
        if not isinstance(v, (list, tuple)) or len(v) not in counts:
            raise bad(f"expected {text} numbers{what}", v)
        return list(v)
    return BeforeValidator(check)


def _matrix3(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if (not isinstance(v, (list, tuple)) or len(v) != 3
            or not all(isinstance(r, (list, tuple)) and len(r) == 3 for r in v)):
        raise bad("expected a 3x3 matrix (3 rows of 3 numbers)", v)
    return [list(r) for r in v]


def _positive_pair(v: list[float]) -> list[float]:
    if not all(x > 0 for x in v):
        raise bad("expected 2 positive numbers", v)
    return v


def _increasing_pair(v: list[float]) -> list[float]:
    if not v[0] < v[1]:
        raise bad("expected [low, high] with low < high", v)
    return v


def _finite(v: float) -> float:
    if not math.isfinite(v):
        raise bad("expected a finite number", v)
    return v


Finite = Annotated[float, AfterValidator(_finite)]
Positive = Annotated[float, Field(gt=0), AfterValidator(_finite)]
Vec2 = Annotated[list[Finite], numbers(2)]
Vec3 = Annotated[list[Finite], numbers(3)]
Matrix3 = Annotated[list[list[Finite]], BeforeValidator(_matrix3)]
PositivePair = Annotated[Vec2, AfterValidator(_positive_pair)]
Range = Annotated[Vec2, AfterValidator(_increasing_pair)]


def dump_json(obj: Any, width: int = 120, indent: int = 1) -> str:
    """JSON text indented by ``indent``, with any list or object that fits in ``width``
    columns kept on one line (a 3x3 matrix, a frame). Non-finite floats are refused."""
    def out(v: Any, level: int) -> str:
        flat = json.dumps(v, allow_nan=False)
        if not isinstance(v, (dict, list)) or not v or len(flat) + indent * level <= width:
            return flat
        pad, inner = " " * (indent * level), " " * (indent * (level + 1))
        if isinstance(v, dict):
            items = [f"{inner}{json.dumps(str(k))}: {out(x, level + 1)}" for k, x in v.items()]
            return "{\n" + ",\n".join(items) + f"\n{pad}}}"
        return "[\n" + ",\n".join(inner + out(x, level + 1) for x in v) + f"\n{pad}]"
    return out(obj, 0) + "\n"
