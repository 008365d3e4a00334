"""The mark job (docs/formats.md, mark job): 3-D paths on the workpiece with laser parameters.

Each path: jump (laser off) to its first point, then mark (laser on) through the rest. Points: (N,
3) float64 arrays, world frame, mm, stored to 1 nm. A path's own ``laser`` overrides the job's,
field by field. ``timing`` (an addition of ours; optional) holds the scan-head delays, µs. A path's
``laser`` may also carry (our additions, optional): ``pen`` (the pen's name), ``passes``,
``delays_us`` and ``wobble`` (:mod:`insitu.formats.pens`) — a job without them marks each path once
with the job's timing and no wobble. Written atomically; read back with validation (one-line
FormatError naming the field).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PlainSerializer, ValidationError

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.bounds import within
from insitu.formats.pens import Delays, Passes, Pen, PenName, Wobble
from insitu.formats.validation import bad, read_json, validation_message

JOB_FORMAT = "insitu-job/1"


def _bad_row(v) -> None:
    for i, p in enumerate(v):
        if (not isinstance(p, (list, tuple)) or len(p) != 3
                or any(isinstance(c, bool) or not isinstance(c, (int, float)) for c in p)):
            raise bad("expected 3 numbers [x, y, z]", p, at=f"[{i}]")


def _points(v: Any) -> np.ndarray:
    """A list of [x, y, z] numbers (or an (N, 3) array) → (N, 3) float64, rounded to 1 nm."""
    if isinstance(v, (list, tuple)):
        if len(v) == 0:
            raise bad("expected at least 1 point", [])
        try:
            arr = np.asarray(v)
        except (ValueError, TypeError):
            arr = None
        if arr is None or arr.ndim != 2 or arr.shape[1] != 3 or arr.dtype.kind not in "iuf":
            _bad_row(v)
            raise bad("expected a list of [x, y, z] points", v)
    elif isinstance(v, np.ndarray):
        arr = v
        if arr.ndim != 2 or arr.shape[1] != 3 or arr.dtype.kind not in "iuf":
            raise bad("expected (N, 3) numbers", f"array of shape {arr.shape}")
    else:
        raise bad("expected a list of [x, y, z] points", v)
    if len(arr) == 0:
        raise bad("expected at least 1 point", [])
    arr = np.asarray(arr, np.float64)
    finite = np.isfinite(arr).all(1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise bad("expected 3 finite numbers", str(arr[i].tolist()), at=f"[{i}]")
    out = np.round(arr, 6)
    out.setflags(write=False)
    return out


Points = Annotated[np.ndarray, BeforeValidator(_points),
                   PlainSerializer(lambda a: a.tolist(), return_type=list)]
Percent = within("power_pct")
Frequency = within("frequency_khz")
MarkSpeed = within("mark_speed_mm_s")
JumpSpeed = within("jump_speed_mm_s")
Delay = within("delay_us")
CornerDeg = within("corner_deg")


class _Model(BaseModel):
    model_config = ConfigDict(extra="allow", allow_inf_nan=False, arbitrary_types_allowed=True,
                              frozen=True)


class LaserParams(_Model):
    """Marking laser: power (% of full), pulse frequency (kHz), mark and jump speeds (mm/s)."""

    power_pct: Percent = 30.0
    frequency_khz: Frequency = 20.0
    mark_speed_mm_s: MarkSpeed = 500.0
    jump_speed_mm_s: JumpSpeed = 3000.0


class LaserOverride(_Model):
    """A path's own laser parameters; None: the job's (``passes``: 1, ``delays_us``: the
    job's timing, ``wobble``: off). ``pen``: the name of the pen they came from."""

    pen: PenName | None = None
    power_pct: Percent | None = None
    frequency_khz: Frequency | None = None
    mark_speed_mm_s: MarkSpeed | None = None
    jump_speed_mm_s: JumpSpeed | None = None
    passes: Passes | None = None
    delays_us: Delays | None = None
    wobble: Wobble | None = None

    @classmethod
    def of_pen(cls, pen: Pen) -> "LaserOverride":
        """Every setting of ``pen`` (wobble only when on)."""
        return cls(pen=pen.name, power_pct=pen.power_pct, frequency_khz=pen.frequency_khz,
                   mark_speed_mm_s=pen.mark_speed_mm_s, jump_speed_mm_s=pen.jump_speed_mm_s,
                   passes=pen.passes, delays_us=pen.delays_us, wobble=pen.wobble)


class Timing(_Model):
    """Scan-head delays, µs. Laser on/off: after laser on / before laser off, mirrors at rest;
    jump: after every jump; mark: after every path; polygon: at a corner, scaled by the turn
    angle / 180° (corners below ``min_corner_deg`` count as straight)."""

    laser_on_delay_us: Delay = 100.0
    laser_off_delay_us: Delay = 150.0
    jump_delay_us: Delay = 250.0
    mark_delay_us: Delay = 150.0
    polygon_delay_us: Delay = 100.0
    min_corner_deg: CornerDeg = 5.0


class MarkPath(_Model):
    points: Points
    laser: LaserOverride | None = None


class MarkJob(_Model):
    """The mark job of docs/formats.md. ``paths`` is the only field a file must have.
    ``rig``: the rig the cloud it was planned on was measured on
    (:mod:`insitu.formats.rig_record`), None when unknown; not part of what is marked
    (:meth:`digest`)."""

    format: Literal["insitu-job/1"] = JOB_FORMAT
    frame: Literal["scan-head"] = "scan-head"
    units: Literal["mm"] = "mm"
    laser: LaserParams = LaserParams()
    timing: Timing | None = None
    rig: dict[Literal["workpiece", "seed", "binning", "rig_file", "pose"],
              str | int | list[float]] | None = None
    paths: Annotated[list[MarkPath], Field(min_length=1)]

    def path_laser(self, i: int) -> LaserParams:
        """The laser parameters path ``i`` is marked with (job's, overridden by the path's)."""
        over = self.paths[i].laser
        if over is None:
            return self.laser
        return self.laser.model_copy(update={k: getattr(over, k) for k in LaserParams.model_fields
                                             if getattr(over, k) is not None})

    def path_timing(self, i: int, timing: Timing | None = None) -> Timing:
        """The delays of path ``i``: its own ``delays_us``, else the job's timing, else
        ``timing``, else the defaults (the corner threshold is always the job's)."""
        base = self.timing or timing or Timing()
        over = self.paths[i].laser
        d = over.delays_us if over is not None else None
        if d is None:
            return base
        return base.model_copy(update={"laser_on_delay_us": d.laser_on,
                                       "laser_off_delay_us": d.laser_off,
                                       "jump_delay_us": d.jump, "mark_delay_us": d.mark,
                                       "polygon_delay_us": d.polygon})

    def path_passes(self, i: int) -> int:
        """How many times path ``i`` is marked (1 unless its ``laser`` says)."""
        over = self.paths[i].laser
        return over.passes if over is not None and over.passes is not None else 1

    def path_wobble(self, i: int) -> Wobble | None:
        over = self.paths[i].laser
        return None if over is None else over.wobble

    def pens(self) -> dict[str, list[int]]:
        """Pen name → the paths marked with it, in order of first use ("" for paths
        without)."""
        out: dict[str, list[int]] = {}
        for i, p in enumerate(self.paths):
            out.setdefault(p.laser.pen if p.laser is not None and p.laser.pen else "", []).append(i)
        return out

    def digest(self) -> str:
        """sha256 of what would be marked (points, lasers, timing): identifies the job. The
        path keys added with pens count only when set (an older job's digest is unchanged)."""
        h = hashlib.sha256()
        h.update(self.laser.model_dump_json().encode())
        h.update((self.timing.model_dump_json() if self.timing else "").encode())
        for p in self.paths:
            h.update(np.ascontiguousarray(p.points).tobytes())
            h.update((p.laser.model_dump_json(exclude=_unset_additions(p.laser))
                      if p.laser else "-").encode())
        return h.hexdigest()


_ADDED = ("pen", "passes", "delays_us", "wobble")


def _unset_additions(over: LaserOverride) -> set[str]:
    return {k for k in _ADDED if getattr(over, k) is None}


def make_job(paths: list[np.ndarray], laser: LaserParams | None = None,
             overrides: dict[int, LaserOverride] | None = None,
             timing: Timing | None = None) -> MarkJob:
    """A job from (N, 3) target arrays; ``overrides``: path index → its own laser."""
    overrides = overrides or {}
    return MarkJob(laser=laser or LaserParams(), timing=timing,
                   paths=[MarkPath(points=p, laser=overrides.get(i)) for i, p in enumerate(paths)])


def with_pen(job: MarkJob, pen: Pen) -> MarkJob:
    """``job`` with every path marked by ``pen`` (its settings in each path's ``laser``)."""
    over = LaserOverride.of_pen(pen)
    return job.model_copy(update={"paths": [p.model_copy(update={"laser": over})
                                            for p in job.paths]})


def job_json(job: MarkJob) -> str:
    """The file's text: header fields indented, one path per line."""
    head = job.model_dump(mode="json", exclude={"paths"}, exclude_none=True)
    lines = ["{"] + [f' {json.dumps(k)}: {json.dumps(v, allow_nan=False)},'
                           for k, v in head.items()]
    lines.append(' "paths": [')
    rows = []
    for p in job.paths:
        d = {"points": p.points.tolist()}
        if p.laser is not None:
            d["laser"] = p.laser.model_dump(mode="json", exclude_none=True)
        extra = {k: v for k, v in (p.model_extra or {}).items()}
        rows.append("  " + json.dumps({**d, **extra}, allow_nan=False))
    lines.append(",\n".join(rows))
    lines += [" ]", "}"]
    return "\n".join(lines) + "\n"


def write_job(path: str | Path, job: MarkJob) -> None:
    """Write ``job`` atomically (temporary file beside ``path``, then renamed)."""
    atomic_write_text(path, job_json(job))


def read_job(path: str | Path) -> MarkJob:
    """Read and validate a job file; FormatError ``file: field: problem`` on any fault."""
    path = Path(path)
    data = read_json(path, missing="no such job file")
    if not isinstance(data, dict):
        raise FormatError(f"{path}: expected a JSON object (a mark job), got {type(data).__name__}")
    try:
        return MarkJob.model_validate(data)
    except ValidationError as e:
        raise FormatError(validation_message(path, e)) from None


# ---------------------------------------------------------------------------- timing
def corner_delays_us(points: np.ndarray, timing: Timing) -> np.ndarray:
    """(N,) polygon delay at each vertex of a mark path, µs: ``polygon_delay_us`` × turn
    angle / 180° at interior vertices turning more than ``min_corner_deg``; 0 at the ends."""
    p = np.asarray(points, float)
    out = np.zeros(len(p))
    if len(p) < 3 or timing.polygon_delay_us == 0:
        return out
    d = np.diff(p, axis=0)
    n = np.linalg.norm(d, axis=1)
    ok = n > 1e-12
    u = np.where(ok[:, None], d / np.where(ok, n, 1.0)[:, None], 0.0)
    cos = np.clip(np.einsum("ij,ij->i", u[:-1], u[1:]), -1, 1)
    ang = np.degrees(np.arccos(cos))
    ang[~(ok[:-1] & ok[1:])] = 0.0
    out[1:-1] = np.where(ang > timing.min_corner_deg, timing.polygon_delay_us * ang / 180.0, 0.0)
    return np.round(out, 1)


@dataclass(frozen=True)
class TimeEstimate:
    """Seconds: total = jump + mark + delays. Lengths in mm (3-D)."""

    total_s: float
    jump_s: float
    mark_s: float
    delay_s: float
    jump_mm: float
    mark_mm: float
    paths: int


def _path_costs(job: MarkJob, timing: Timing | None, start, first_path: int):
    """Per path from ``first_path`` on: (jump mm, mark mm, jump s, mark s, delays s) — each
    pass its jump (the first from where the last path ended, the others back to the path's
    start), its marks and its delays (jump, laser on and off, mark, polygon at corners)."""
    pos = np.asarray(start, float)
    for i in range(first_path, len(job.paths)):
        pts, las, t = job.paths[i].points, job.path_laser(i), job.path_timing(i, timing)
        n = job.path_passes(i)
        m = n * float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
        j = float(np.linalg.norm(pts[0] - pos)) + (n - 1) * float(np.linalg.norm(pts[-1] - pts[0]))
        per_pass_us = (t.jump_delay_us + t.laser_on_delay_us + t.laser_off_delay_us
                       + t.mark_delay_us + float(corner_delays_us(pts, t).sum()))
        yield j, m, j / las.jump_speed_mm_s, m / las.mark_speed_mm_s, n * per_pass_us * 1e-6
        pos = pts[-1]


def estimate_time(job: MarkJob, timing: Timing | None = None, start=(0.0, 0.0, 0.0),
                  first_path: int = 0) -> TimeEstimate:
    """Marking time of the job from path ``first_path`` on, starting at ``start`` (3,) mm:
    jumps at each path's jump speed, marks at its mark speed, every pass with the path's
    delays. ``timing``: the job's, else this, else defaults."""
    c = np.array(list(_path_costs(job, timing, start, first_path))).reshape(-1, 5).sum(0)
    jump_mm, mark_mm, jump_s, mark_s, delay_s = map(float, c)
    return TimeEstimate(jump_s + mark_s + delay_s, jump_s, mark_s, delay_s, jump_mm, mark_mm,
                        len(job.paths) - first_path)


def path_seconds(job: MarkJob, timing: Timing | None = None) -> np.ndarray:
    """(N,) estimated seconds of each path (its passes, jumps and delays included)."""
    c = np.array(list(_path_costs(job, timing, (0.0, 0.0, 0.0), 0))).reshape(-1, 5)
    return c[:, 2:].sum(1)
