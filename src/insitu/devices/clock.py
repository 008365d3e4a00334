"""The station's own time: the seconds its devices take — camera frames, the head's lines and
jumps, marking, the stage — kept apart from the computer's.

The devices advance a :class:`StationClock` as they work; a use case reads it before and
after a step (``clock.now()``, then ``clock.now() - before`` is a :class:`StationTime`).
The simulated rig's devices advance it by what each would take on a real station
(:mod:`insitu.sim.clock` holds their timing); a real rig's devices do not, and a real
station has no such clock (``Station.clock`` is None): its time is the wall clock's.

What the simulator itself spends drawing frames is CPU time a real station does not spend;
the simulated devices count it in ``simulation_cpu_s`` (:meth:`StationClock.simulating`),
so that a step's processing CPU is its CPU time less that.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field

KINDS = ("frames", "marking", "stage")
"""What spends station time: camera frames (with the head's lines, jumps and settling that
set them), marking (the controller's lists), the Z stage."""


@dataclass(frozen=True)
class StationTime:
    """Station seconds by what spent them (``by``: a key of :data:`KINDS` → seconds), and
    the simulator's own CPU seconds over the same span (``simulation_cpu_s``)."""

    by: Mapping[str, float] = field(default_factory=dict)
    simulation_cpu_s: float = 0.0

    @property
    def seconds(self) -> float:
        """All station seconds."""
        return float(sum(self.by.values()))

    def __sub__(self, before: "StationTime") -> "StationTime":
        keys = set(self.by) | set(before.by)
        return StationTime({k: self.by.get(k, 0.0) - before.by.get(k, 0.0) for k in keys},
                           self.simulation_cpu_s - before.simulation_cpu_s)

    def __add__(self, other: "StationTime") -> "StationTime":
        keys = set(self.by) | set(other.by)
        return StationTime({k: self.by.get(k, 0.0) + other.by.get(k, 0.0) for k in keys},
                           self.simulation_cpu_s + other.simulation_cpu_s)


class StationClock:
    """The station's time, advanced by its devices. Thread-safe enough for one writer per
    kind (the camera, the controller, the stage each advance their own)."""

    def __init__(self) -> None:
        self._by: dict[str, float] = {k: 0.0 for k in KINDS}
        self._simulation_cpu_s = 0.0

    def advance(self, kind: str, seconds: float) -> None:
        """``seconds`` (≥ 0) more of ``kind`` (a key of :data:`KINDS`)."""
        if kind not in self._by:
            raise ValueError(f"station clock: kind {kind!r}: expected one of {', '.join(KINDS)}")
        if not seconds >= 0:
            raise ValueError(f"station clock: {seconds!r} s: expected ≥ 0")
        self._by[kind] += float(seconds)

    def now(self) -> StationTime:
        """The time so far (subtract an earlier ``now()`` for a span)."""
        return StationTime(dict(self._by), self._simulation_cpu_s)

    @contextmanager
    def simulating(self) -> Iterator[None]:
        """Count the CPU seconds the calling thread spends inside as the simulator's (a
        scan's processing may run beside it on another thread)."""
        t0 = time.thread_time()
        try:
            yield
        finally:
            self._simulation_cpu_s += time.thread_time() - t0


@dataclass(frozen=True)
class StepTime:
    """One step's seconds: ``station`` (its devices' own time; None on a real rig, whose
    time is the wall clock's), ``cpu`` (the computer's processing, simulation excluded,
    ``time.process_time`` of the process) and ``wall`` (the wall clock's, simulation
    included)."""

    station: float | None
    cpu: float
    wall: float


class StepTimer:
    """Times one step on a station clock (None: a real rig) from its making on:
    :meth:`elapsed` so far, or ``with StepTimer(clock) as t:`` … then ``t.result``."""

    def __init__(self, clock: StationClock | None):
        self.clock = clock
        self.result: StepTime | None = None
        self._t0 = (time.process_time(), time.perf_counter(),
                    clock.now() if clock is not None else None)

    def elapsed(self) -> StepTime:
        """The step's :class:`StepTime` so far."""
        cpu0, wall0, st0 = self._t0
        spent = self.clock.now() - st0 if self.clock is not None else None
        cpu = time.process_time() - cpu0 - (spent.simulation_cpu_s if spent else 0.0)
        return StepTime(spent.seconds if spent is not None else None, max(cpu, 0.0),
                        time.perf_counter() - wall0)

    def __enter__(self) -> "StepTimer":
        return self

    def __exit__(self, *exc) -> None:
        self.result = self.elapsed()
