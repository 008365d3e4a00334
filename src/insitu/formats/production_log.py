"""The log of a production run: one record per part attempt, as JSON lines (the truth,
appended and fsynced as each part ends) and as CSV beside it (rewritten atomically from the
JSON lines after each record, for a spreadsheet).

    {"part": 7, "serial": 7, "outcome": "marked", "x_mm": 3.1, "y_mm": -12.0,
     "angle_deg": 131.5, "fitness": 0.97, "rmse_mm": 0.02, "image_edges": 1104,
     "decoded": "00007",
     "decode_ok": true, "grade": "A", "offset_mm": 0.03, "job": "part-0007.job.json",
     "scan_s": 1.2, "rescan_s": null, "locate_s": 0.4, "plan_s": 0.3, "mark_s": 0.8,
     "read_s": 0.5, "scan_station_s": 0.9, "scan_cpu_s": 0.7, ..., "read_station_s": 0.2,
     "read_cpu_s": 0.4, "error": null, "resumed": false, "time": "2026-12-02T05:01:02+00:00"}

Per stage (``scan``, ``rescan``, ``locate``, ``plan``, ``mark``, ``read``): ``<stage>_s`` the
wall clock's seconds, ``<stage>_station_s`` the station's own (its devices' time: camera
frames, the head, marking; null on a real rig, whose time is the wall clock's, and 0 for a
stage that drives no device) and ``<stage>_cpu_s`` the computer's processing
(``time.process_time``; on the simulated rig the simulator's drawing is left out).

``image_edges``: the room-light frame's edge points that gave x, y and the turn (0: the scan lines'
edges did). ``rescan_s``: the second look's crossed scan (null: none). ``outcome``: "marked" (marked
and read back), "refused" (not located or not planned: no serial taken, the part set aside), "fault"
(a device failed: the laser is off, the run stopped) or "aborted" (the operator stopped the run). A
part's last record is its outcome; a fault or an abort after its serial was issued keeps that serial
in the record, and ``--resume`` finishes the same part with it. A "marked" part whose read-back
fails (a mark not the plan, or ``offset_mm`` beyond the recipe's ``read.offset_tolerance_mm``)
carries the reason in ``error``.
"""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, ValidationError

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.counter import Serial
from insitu.formats.limits import read_limited
from insitu.formats.validation import validation_message

MAX_LOG_BYTES = 64 << 20
OUTCOMES = ("marked", "refused", "fault", "aborted")
STAGES = ("scan", "rescan", "locate", "plan", "mark", "read")


class PartRecord(BaseModel):
    """One line of the log (see the module's docstring); times in seconds per stage."""

    model_config = ConfigDict(extra="allow", frozen=True, allow_inf_nan=False)
    part: int
    serial: Serial | None = None
    outcome: Literal["marked", "refused", "fault", "aborted"]
    x_mm: float | None = None
    y_mm: float | None = None
    angle_deg: float | None = None
    fitness: float | None = None
    rmse_mm: float | None = None
    image_edges: int | None = None
    decoded: str | None = None
    decode_ok: bool | None = None
    grade: str | None = None
    offset_mm: float | None = None
    job: str | None = None
    scan_s: float | None = None
    rescan_s: float | None = None
    locate_s: float | None = None
    plan_s: float | None = None
    mark_s: float | None = None
    read_s: float | None = None
    scan_station_s: float | None = None
    rescan_station_s: float | None = None
    locate_station_s: float | None = None
    plan_station_s: float | None = None
    mark_station_s: float | None = None
    read_station_s: float | None = None
    scan_cpu_s: float | None = None
    rescan_cpu_s: float | None = None
    locate_cpu_s: float | None = None
    plan_cpu_s: float | None = None
    mark_cpu_s: float | None = None
    read_cpu_s: float | None = None
    error: str | None = None
    resumed: bool = False
    time: str


COLUMNS = tuple(PartRecord.model_fields)


def csv_path_for(log: str | Path) -> Path:
    """The CSV beside the JSON-lines log (``run.jsonl`` → ``run.csv``)."""
    return Path(log).with_suffix(".csv")


def read_log(path: str | Path) -> list[PartRecord]:
    """The records of the log (empty when it does not exist); FormatError naming the line.
    A last line cut short by a crash is ignored (it was never fsynced whole)."""
    path = Path(path)
    if not path.exists():
        return []
    lines = read_limited(path, MAX_LOG_BYTES, "production log").decode("utf-8",
                                                                       "replace").split("\n")
    out = []
    for i, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            out.append(PartRecord.model_validate(json.loads(line)))
        except json.JSONDecodeError:
            if i == len(lines):             # the unterminated last line of a crash
                break
            raise FormatError(f"{path}: line {i}: not JSON") from None
        except ValidationError as e:
            raise FormatError(validation_message(f"{path}: line {i}", e)) from None
    return out


def append_record(path: str | Path, record: PartRecord) -> None:
    """Append ``record`` to the JSON-lines log (fsynced), then rewrite the CSV beside it."""
    path = Path(path)
    line = json.dumps(record.model_dump(mode="json"), ensure_ascii=False) + "\n"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    try:
        os.write(fd, line.encode("utf-8"))
        os.fsync(fd)
    finally:
        os.close(fd)
    write_csv(csv_path_for(path), read_log(path))


def write_csv(path: str | Path, records: list[PartRecord]) -> None:
    """The records as CSV (one column per field, empty for None), written atomically."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    for r in records:
        d: dict[str, Any] = r.model_dump(mode="json")
        w.writerow(["" if d[c] is None else d[c] for c in COLUMNS])
    atomic_write_text(path, buf.getvalue())


def last_by_part(records: list[PartRecord]) -> dict[int, PartRecord]:
    """Each part's last record (its outcome)."""
    return {r.part: r for r in records}
