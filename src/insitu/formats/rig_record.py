"""Which rig a cloud was measured on and a job planned for (docs/formats.md, rig record): a flat
JSON object — the simulated rig's ``workpiece``, ``seed`` and ``binning``, or a real rig's
``rig_file`` (its name; with simulated devices also ``workpiece`` and ``seed``), and on the
simulated rig the part's ``pose`` [x mm, y mm, turn °] when it is not at the origin. The
binning changes only the camera's pixels, so two records name the same rig when all else
agrees; the same part put down elsewhere is another placement: a job planned on its cloud
would miss it."""

from __future__ import annotations

import json
import math
from pathlib import Path

from insitu.errors import FormatError

RigRecord = dict[str, str | int | list[float]]
_KEYS = {"workpiece": str, "seed": int, "binning": int, "rig_file": str, "pose": list}
NO_POSE = [0.0, 0.0, 0.0]
PLY_COMMENT = "insitu-rig"


def describe(record: RigRecord) -> str:
    """"rig file rig.json, workpiece arc, seed 0" or "simulated rig, workpiece arc, seed 0,
    binning 1"."""
    head = f"rig file {record['rig_file']}" if "rig_file" in record else "simulated rig"
    out = ", ".join([head] + [f"{k} {record[k]}" for k in ("workpiece", "seed", "binning")
                              if k in record])
    if "pose" in record:
        x, y, a = record["pose"]
        out += f", at x {x:g} y {y:g} mm turned {a:g}°"
    return out


def same_rig(a: RigRecord, b: RigRecord) -> bool:
    """Whether ``a`` and ``b`` name the same rig and workpiece (binning aside)."""
    strip = lambda r: {k: v for k, v in r.items() if k not in ("binning", "pose")}  # noqa: E731
    pa, pb = a.get("pose", NO_POSE), b.get("pose", NO_POSE)
    return strip(a) == strip(b) and all(abs(u - v) < 1e-6 for u, v in zip(pa, pb))


def parse(path: Path, where: str, value) -> RigRecord:
    """``value`` checked as a record (keys and types above); FormatError naming ``path`` and
    ``where`` (the field or header line) otherwise."""
    if not isinstance(value, dict) or not value or any(
            k not in _KEYS or type(v) is not _KEYS[k] for k, v in value.items()) or (
            "pose" in value and not _is_pose(value["pose"])):
        raise FormatError(f"{path}: {where}: expected an object of {', '.join(_KEYS)} "
                          f"(text, whole numbers, pose [x, y, degrees]), got "
                          f"{json.dumps(value)[:80]}")
    return value


def _is_pose(v: list) -> bool:
    return len(v) == 3 and all(type(u) in (int, float) and math.isfinite(u) for u in v)


def ply_line(record: RigRecord) -> bytes:
    """The PLY header line carrying ``record``."""
    return f"comment {PLY_COMMENT} {json.dumps(record, sort_keys=True)}\n".encode("ascii")


def from_ply_header(path: Path, header: str) -> RigRecord | None:
    """The record of the header text ``header``, None when it has none."""
    for n, line in enumerate(header.splitlines(), start=1):
        words = line.split(None, 2)
        if words[:2] == ["comment", PLY_COMMENT]:
            where = f"header line {n} ({PLY_COMMENT})"
            try:
                value = json.loads(words[2] if len(words) == 3 else "")
            except ValueError:
                raise FormatError(f"{path}: {where}: not a JSON object") from None
            return parse(path, where, value)
    return None
