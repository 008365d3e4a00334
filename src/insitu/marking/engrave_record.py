"""The record of an engraving: ``REPORT_DIR/engrave.json``, rewritten atomically after every
step (a round planned, marked, measured), so that a resume knows what was asked, what each
cell has had and what every measurement said. Each round's mark job lies beside it
(``round-NN.json``) with its own journal (:mod:`insitu.marking.journal`)::

    {"format": "insitu-engraving/1", "state": "running",
     "request": {"pattern": "text:\\"AB\\"", "at_mm": [0, 0], "width_mm": 10, ...},
     "material": {... the table's entry it was engraved with ...}, "nominal_rate_mm": 0.0057,
     "cells": {"origin": [x, y], "cell_mm": 0.25, "shape": [ny, nx]},
     "history": {"passes": [[...]], ...}, "layers": 42,
     "rounds": [{"job": "round-01.json", "layers": 9, "paths": 2800, "state": "marked",
                 "passes": [[...]], "marking_s": 21.6, "measure": {...}}, ...],
     "outcome": null}

``state``: running | cancelled | interrupted | done | held (stopped with cells the camera
cannot see short of the target) | refused.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, ValidationError

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.validation import dump_json, read_json, validation_message

RECORD_FORMAT = "insitu-engraving/1"
RECORD_NAME = "engrave.json"
State = Literal["running", "cancelled", "interrupted", "done", "held", "refused"]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=True)


class EngraveAsk(_Model):
    """What was asked: the placement, the depth, how often to measure, the material."""

    pattern: str
    at_mm: tuple[float, float]
    width_mm: float | None = None
    rotate_deg: float = 0.0
    depth_mm: float
    rescan_every: int
    material: str
    open_loop_passes: int | None = None


class RoundRecord(_Model):
    """One round: its job file, layers and paths, ``state`` (planned: sent or about to be;
    marked: every path done; cut: stopped early, its passes counted from the journal),
    ``passes`` (ny, nx) planned per cell with the material's pen, then ``finish`` (ny, nx)
    finishing passes with ``finish_pen`` (its settings; each pass ``1 / finish_speed`` of
    the pen's), ``finishing``: the round has finishing passes; the station's marking seconds
    and the ``measure`` that followed (None: none yet)."""

    job: str
    layers: int
    paths: int
    state: Literal["planned", "marked", "cut"] = "planned"
    finishing: bool = False
    passes: list[list[int]]
    finish: list[list[int]] | None = None
    finish_pen: dict[str, Any] | None = None
    finish_speed: float = 1.0
    marking_s: float = 0.0
    measure: dict[str, Any] | None = None


class EngraveRecord(_Model):
    format: Literal["insitu-engraving/1"] = RECORD_FORMAT
    state: State = "running"
    request: EngraveAsk
    material: dict[str, Any]
    nominal_rate_mm: float
    cells: dict[str, Any]
    history: dict[str, Any]
    layers: int = 0
    rounds: list[RoundRecord] = []
    measures: list[dict[str, Any]] = []
    outcome: dict[str, Any] | None = None


def record_path(report_dir: str | Path) -> Path:
    return Path(report_dir) / RECORD_NAME


def read_record(report_dir: str | Path) -> EngraveRecord | None:
    """The record in ``report_dir`` (None: none); FormatError naming the file and field."""
    path = record_path(report_dir)
    if not path.exists():
        return None
    raw = read_json(path)
    if not isinstance(raw, dict) or raw.get("format") != RECORD_FORMAT:
        raise FormatError(f"{path}: format: expected {RECORD_FORMAT!r} (not an engraving "
                          "record)")
    try:
        return EngraveRecord.model_validate(raw)
    except ValidationError as e:
        raise FormatError(validation_message(path, e)) from None


def write_record(report_dir: str | Path, record: EngraveRecord) -> None:
    atomic_write_text(record_path(report_dir), dump_json(record.model_dump(mode="json")))
