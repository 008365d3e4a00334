"""Pens: named laser sets, as EZCAD, SAMLight and LightBurn operators know them. Each placed
pattern names its pen; the job carries the pen's settings in every path's ``laser``
(:class:`insitu.marking.job.LaserOverride`). A pens file, or a project's ``pens``::

    {"format": "insitu-pens/1", "default": "mark",
     "pens": [{"name": "deep", "colour": "#ff8000", "power_pct": 80, "frequency_khz": 20,
               "mark_speed_mm_s": 200, "jump_speed_mm_s": 3000, "passes": 2,
               "delays_us": {"laser_on": 100, "laser_off": 150, "jump": 250, "mark": 150,
                             "polygon": 100},
               "wobble": {"amplitude_mm": 0.1, "frequency_hz": 500}}, ...]}

``wobble``: null (off) or a circle of ``amplitude_mm`` radius superimposed on the path,
``frequency_hz`` turns per second or ``pitch_mm`` along the path per turn (then the
frequency is mark speed / pitch). Every number has its range in :mod:`.bounds`; an error
names the file, the pen and the field in one line.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.bounds import within
from insitu.formats.validation import (
    bad,
    dump_json,
    one_of,
    read_json,
    show,
    unique_names,
    validation_message,
)

PENS_FORMAT = "insitu-pens/1"
_COLOUR = re.compile(r"^#[0-9a-fA-F]{6}$")


def _name(v: str) -> str:
    if not v.strip() or len(v) > 40 or any(ord(c) < 32 for c in v):
        raise bad("expected a name of 1 … 40 printable characters", v)
    return v


def _colour(v: str) -> str:
    if not _COLOUR.match(v):
        raise bad("expected a colour #rrggbb", v)
    return v.lower()


PenName = Annotated[str, AfterValidator(_name)]
Colour = Annotated[str, AfterValidator(_colour)]
Delay = within("delay_us")
Amplitude, Hz, Pitch = (within("wobble_amplitude_mm"), within("wobble_hz"),
                        within("wobble_pitch_mm"))
Percent, Frequency = within("power_pct"), within("frequency_khz")
MarkSpeed, JumpSpeed, Passes = (within("mark_speed_mm_s"), within("jump_speed_mm_s"),
                                within("passes", int))


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class Delays(_Strict):
    """Scan-head delays, µs: after laser on / before laser off (mirrors at rest), after every
    jump, after every mark sequence, at a 180° corner (scaled by the turn)."""

    laser_on: Delay = 100.0
    laser_off: Delay = 150.0
    jump: Delay = 250.0
    mark: Delay = 150.0
    polygon: Delay = 100.0


class Wobble(_Strict):
    """A circle of ``amplitude_mm`` radius traced around the moving spot, ``frequency_hz``
    turns per second, or one turn per ``pitch_mm`` of path (exactly one of the two)."""

    amplitude_mm: Amplitude
    frequency_hz: Hz | None = None
    pitch_mm: Pitch | None = None

    @model_validator(mode="after")
    def _one_rate(self) -> "Wobble":
        if (self.frequency_hz is None) == (self.pitch_mm is None):
            raise bad("expected exactly one of frequency_hz and pitch_mm")
        return self

    def hz(self, mark_speed_mm_s: float) -> float:
        """Turns per second at ``mark_speed_mm_s``."""
        return self.frequency_hz if self.frequency_hz is not None else (
            mark_speed_mm_s / self.pitch_mm)


class Pen(_Strict):
    """One laser set: power (% of full), pulse frequency (kHz), mark and jump speeds (mm/s),
    ``passes`` over each path, ``delays_us``, ``wobble`` (None: off) and the ``colour`` its
    paths are drawn in."""

    name: PenName
    colour: Colour = "#ff00ff"
    power_pct: Percent = 30.0
    frequency_khz: Frequency = 20.0
    mark_speed_mm_s: MarkSpeed = 500.0
    jump_speed_mm_s: JumpSpeed = 3000.0
    passes: Passes = 1
    delays_us: Delays = Delays()
    wobble: Wobble | None = None

    def summary(self) -> str:
        """One line: ``80 %, 20 kHz, 200 mm/s, 2 passes, wobble 0.1 mm 500 Hz``."""
        text = (f"{self.power_pct:g} %, {self.frequency_khz:g} kHz, {self.mark_speed_mm_s:g} "
                f"mm/s, jump {self.jump_speed_mm_s:g} mm/s, {self.passes} "
                f"pass{'es' * (self.passes != 1)}")
        if self.wobble is not None:
            w = self.wobble
            rate = (f"{w.frequency_hz:g} Hz" if w.frequency_hz is not None
                    else f"pitch {w.pitch_mm:g} mm")
            text += f", wobble {w.amplitude_mm:g} mm {rate}"
        return text


class PenTable(_Strict):
    """The pens of a project or a pens file; ``default``: the pen of a placement that names
    none."""

    default: PenName
    pens: Annotated[tuple[Pen, ...], Field(min_length=1)]

    @model_validator(mode="after")
    def _names(self) -> "PenTable":
        seen = unique_names(self.pens, "pen", "pens")
        if self.default not in seen:
            raise bad(f"expected one of the pens, {one_of(seen)}", self.default, at="default")
        return self

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.pens)

    def pen(self, name: str | None, where: str = "pen") -> Pen:
        """The pen called ``name`` (None: the default); FormatError naming ``where`` and the
        pens there are."""
        name = self.default if name is None else name
        for p in self.pens:
            if p.name == name:
                return p
        raise FormatError(f"{where}: no pen {name!r}; the pens are {one_of(self.names)}",
                          field="pen" if where == "pen" else None)

    def replaced(self, pen: Pen, old_name: str | None = None) -> "PenTable":
        """The table with ``pen`` in place of ``old_name`` (default: ``pen.name``), or added."""
        old = pen.name if old_name is None else old_name
        pens = [pen if p.name == old else p for p in self.pens]
        if old not in self.names:
            pens.append(pen)
        return PenTable(default=pen.name if self.default == old else self.default,
                        pens=tuple(pens))


DEFAULT_PENS = PenTable(default="mark", pens=(
    Pen(name="mark", colour="#ff4dff"),
    Pen(name="fine", colour="#00c8ff", power_pct=20.0, frequency_khz=60.0,
        mark_speed_mm_s=300.0, delays_us=Delays(laser_on=80.0, laser_off=120.0)),
    Pen(name="deep", colour="#ff8000", power_pct=80.0, frequency_khz=20.0,
        mark_speed_mm_s=200.0, passes=2),
    Pen(name="bold", colour="#40ff40", power_pct=40.0, mark_speed_mm_s=400.0,
        wobble=Wobble(amplitude_mm=0.1, frequency_hz=500.0)),
))
"""The pens of a new project: "mark" is the laser a job gets without pens (30 %, 20 kHz,
500 mm/s, the default delays), "fine" for small text, "deep" engraves in 2 passes, "bold"
widens the line with a 0.1 mm wobble."""


def pen_table(pens: Any, default: Any, source: str | Path,
              default_field: str = "default") -> PenTable:
    """Validate a pen table: ``pens`` a list of pen objects, ``default`` a pen's name (None:
    the first pen). FormatError ``source: pens[2] ('deep').power_pct: 120 is outside 0 …
    100 %`` (``default_field`` names where the default is given)."""
    if not isinstance(pens, list) or not pens:
        raise FormatError(f"{source}: pens: expected a list of at least 1 pen, got "
                          f"{show(pens)}")
    table: list[Pen] = []
    for i, raw in enumerate(pens):
        name = raw.get("name") if isinstance(raw, dict) else None
        label = f" ({name!r})" if isinstance(name, str) and name.strip() else ""
        try:
            table.append(Pen.model_validate(raw))
        except ValidationError as e:
            raise FormatError(validation_message(source, e, f"pens[{i}]{label}")) from None
        if table[-1].name in [p.name for p in table[:-1]]:
            raise FormatError(f"{source}: pens[{i}].name: pen {name!r} is defined twice")
    names = [p.name for p in table]
    default = names[0] if default is None else default
    if default not in names:
        raise FormatError(f"{source}: {default_field}: expected one of the pens, "
                          f"{one_of(names)}, got {show(default)}")
    return PenTable(default=default, pens=tuple(table))


def pens_dict(table: PenTable) -> dict:
    """The table as JSON-ready data (no format field)."""
    return table.model_dump(mode="json", exclude_none=True)


def read_pens(path: str | Path) -> PenTable:
    """Read a pens file (``format`` insitu-pens/1); FormatError naming the file, pen, field."""
    path = Path(path)
    raw = read_json(path, missing="no such pens file")
    if not isinstance(raw, dict) or raw.get("format") != PENS_FORMAT:
        got = raw.get("format") if isinstance(raw, dict) else type(raw).__name__
        raise FormatError(f"{path}: format: expected {PENS_FORMAT!r}, got {got!r} "
                          "(not a pens file)")
    extra = sorted(set(raw) - {"format", "default", "pens"})
    if extra:
        raise FormatError(f"{path}: {extra[0]}: not a known field")
    return pen_table(raw.get("pens"), raw.get("default"), path)


def write_pens(path: str | Path, table: PenTable) -> None:
    """Write a pens file atomically."""
    atomic_write_text(path, dump_json({"format": PENS_FORMAT, **pens_dict(table)}))

