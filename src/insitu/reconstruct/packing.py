"""The frames of a scan: one line each, or several lines per exposure packed so that their
bands never share a pixel (:mod:`insitu.reconstruct.bands`).

Packed frames need the heights the surface can have: narrower than the head's focus range, or the
bands of lines a few millimetres apart overlap. First *survey* frames measure them: the region's
first and last lines and lines every third of the focus-range stride between
(:func:`~insitu.reconstruct.bands.survey`), those of one frame as far apart as the whole focus
range's bands need, so they tell their lines apart with no height range; the heights they measured,
widened by :attr:`~insitu.reconstruct.bands.Packing.height_mm`, then bound every other frame's
bands. Their lines are measured again in the packed frames (a survey gives heights only). A height
range known beforehand (a recipe's part, the operator's) takes its place.

``lines_per_frame``: None or 1, one line a frame (no survey); an int K, the lines of each pass
dealt into ⌈N / K⌉ frames of lines ⌈N / K⌉ lines apart (where their bands still overlap, those
pixels give no point); ``"auto"``, as many per frame as the measured heights allow, at most
:attr:`~insitu.reconstruct.bands.Packing.most_lines`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from insitu.errors import ConfigError
from insitu.reconstruct.bands import Packing, Sheets, frames, stride, survey
from insitu.reconstruct.turned_sheet import line_angle, turned_offset

AUTO = "auto"


@dataclass(frozen=True)
class Frame:
    """One exposure: its ``lines`` ((start, end) mm each), their ``ids`` (each line's place
    across its pass, passes one after the other: the cloud's ``line``), and whether it is a
    ``survey`` frame (its points bound the heights, and are not kept)."""

    lines: tuple
    ids: tuple
    survey: bool = False


def lines_per_frame(value: str | int | None) -> int | str | None:
    """``--lines-per-frame``: "auto", or a whole number ≥ 1 (None: one); ConfigError else."""
    if value is None or value == AUTO:
        return value
    try:
        k = int(value)
    except (TypeError, ValueError):
        k = 0
    if k < 1 or str(value).strip() not in (str(k), f"{k}.0"):
        raise ConfigError(f"lines per frame {value!r}: expected 'auto' or a whole number ≥ 1",
                          field="lines_per_frame")
    return k


def passes(lines: Sequence) -> list[list[int]]:
    """The indices of ``lines`` by pass (lines of one direction), each in order across its
    pass (by offset)."""
    by_angle: dict[float, list[int]] = {}
    for i, (a, b) in enumerate(lines):
        by_angle.setdefault(round(line_angle(a, b), 6), []).append(i)
    out = []
    for angle, idx in sorted(by_angle.items()):
        key = [turned_offset(lines[i][0], lines[i][1], angle) for i in idx]
        out.append([idx[j] for j in np.argsort(key, kind="stable")])
    return out


def line_ids(lines: Sequence) -> list[int]:
    """Each line's place across its pass, passes one after the other (the cloud's ``line``:
    neighbouring ids are neighbouring lines)."""
    ids = [0] * len(lines)
    k = 0
    for p in passes(lines):
        for i in p:
            ids[i] = k
            k += 1
    return ids


class FramePlan:
    """The frames of a live scan of ``lines`` ((start, end) mm each, in plan order).
    ``sheets``: the rig's light sheets; ``focus_range``: the head's (low, high) mm;
    ``per_frame``: see the module docstring; ``heights``: the surface's (low, high) mm when
    known beforehand (then no survey)."""

    def __init__(self, lines: Sequence, sheets: Sheets, focus_range: tuple[float, float],
                 per_frame: int | str | None = None, packing: Packing = Packing(),
                 heights: tuple[float, float] | None = None):
        self.lines = [(np.asarray(a, float), np.asarray(b, float)) for a, b in lines]
        self.sheets, self.focus_range, self.packing = sheets, tuple(focus_range), packing
        self.per_frame = lines_per_frame(per_frame)
        self.heights = heights
        self.ids = line_ids(self.lines)
        self.z_range: tuple[float, float] = self.focus_range
        self.gap_mm: float | None = None

    @property
    def packed(self) -> bool:
        return self.per_frame not in (None, 1)

    def surveys(self) -> list[Frame]:
        """The survey frames (none: one line a frame, or heights known)."""
        if not self.packed or self.heights is not None or not self.lines:
            return []
        first = passes(self.lines)[0]
        bands = [self.sheets.band(*self.lines[i], self.focus_range, self.packing.margin_px)
                 for i in first]
        return [Frame(tuple(self.lines[first[j]] for j in f),
                      tuple(self.ids[first[j]] for j in f), True)
                for f in survey(bands, self.packing.guard_px)]

    def frames(self, measured: tuple[float, float] | None = None) -> list[Frame]:
        """Every frame of the scan; packed ones by the heights known or ``measured`` by the
        survey (widened by the packing's margin, within the focus range; neither: the
        focus range). Sets :attr:`z_range` (the packed frames' heights) and :attr:`gap_mm`
        (the least distance between two lines of one packed frame)."""
        if not self.packed:
            return [Frame((line,), (k,)) for line, k in zip(self.lines, self.ids)]
        self.z_range = self._range(measured)
        out, gaps = [], []
        for p in passes(self.lines):
            bands = [self.sheets.band(*self.lines[i], self.z_range, self.packing.margin_px)
                     for i in p]
            most = self.packing.most_lines if self.per_frame == AUTO else self.per_frame
            s = int(np.ceil(len(p) / most))
            if self.per_frame == AUTO:
                s = max(s, stride(bands, self.packing.guard_px))
            for f in frames(len(p), s):
                pick = [p[j] for j in f]
                out.append(Frame(tuple(self.lines[i] for i in pick),
                                 tuple(self.ids[i] for i in pick)))
                gaps += [_distance(self.lines[i], self.lines[j]) for i, j in zip(pick, pick[1:])]
        self.gap_mm = min(gaps) if gaps else None
        return out

    def _range(self, measured) -> tuple[float, float]:
        known = self.heights if self.heights is not None else measured
        if known is None:
            return self.focus_range
        m = self.packing.height_mm if self.heights is None else 0.0
        lo, hi = self.focus_range
        return max(lo, known[0] - m), min(hi, known[1] + m)


def _distance(a, b) -> float:
    """How far apart two parallel lines are, mm."""
    d = np.subtract(a[1], a[0])
    n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
    return float(abs(np.dot(np.subtract(b[0], a[0]), n)))


class RecordedPlan:
    """The frames of a recorded scan as they were taken: ``drawn`` (each frame's lines,
    (start, end) mm each) and ``surveys`` (which are survey frames). A recording of one line
    a frame keeps its frame indices as line ids (as before it could hold several); else each
    line's place across its pass. Its packed frames' heights: ``heights`` when known, else
    the survey's measured ones widened by the packing's margin, else the focus range (the
    bands of its lines may then share pixels, which give no point)."""

    def __init__(self, drawn: Sequence, surveys: Sequence[bool],
                 focus_range: tuple[float, float], packing: Packing = Packing(),
                 heights: tuple[float, float] | None = None):
        self.drawn = [tuple((np.asarray(a, float), np.asarray(b, float)) for a, b in f)
                      for f in drawn]
        self.is_survey, self.focus_range = list(surveys), tuple(focus_range)
        self.packing, self.heights = packing, heights
        self.packed = any(len(f) > 1 for f in self.drawn) or any(self.is_survey)
        self.z_range: tuple[float, float] = self.focus_range
        self.gap_mm: float | None = None
        kept = [line for f, s in zip(self.drawn, self.is_survey) if not s for line in f]
        self._ids = line_ids(kept) if self.packed else list(range(len(kept)))

    def surveys(self) -> list[Frame]:
        """The survey frames the recording starts with."""
        lead = next((i for i, s in enumerate(self.is_survey) if not s), len(self.is_survey))
        firsts = np.cumsum([0] + [len(f) for f in self.drawn[:lead]])
        return [Frame(f, tuple(range(k, k + len(f))), True)
                for f, k in zip(self.drawn[:lead], firsts)]

    def frames(self, measured: tuple[float, float] | None = None) -> list[Frame]:
        """The frames after the survey frames, in order (a later survey frame kept as one:
        its points are not used); sets :attr:`z_range` and :attr:`gap_mm`."""
        known = self.heights if self.heights is not None else measured
        m = self.packing.height_mm if self.heights is None else 0.0
        if known is not None:
            self.z_range = (max(self.focus_range[0], known[0] - m),
                            min(self.focus_range[1], known[1] + m))
        out, gaps, ids_left = [], [], iter(self._ids)
        start = len(self.surveys())
        for f, s in zip(self.drawn[start:], self.is_survey[start:]):
            ids = tuple(range(len(f))) if s else tuple(next(ids_left) for _ in f)
            out.append(Frame(f, ids, s))
            if not s and len(f) > 1:
                o = np.argsort([turned_offset(a, b, line_angle(a, b)) for a, b in f])
                gaps += [_distance(f[i], f[j]) for i, j in zip(o, o[1:])]
        self.gap_mm = min(gaps) if gaps else None
        return out
