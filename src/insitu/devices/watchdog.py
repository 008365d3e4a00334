"""Heartbeat watchdog: no command reaches the laser without a live answer from the controller.

A real controller feeds the watchdog on every answer from its board (:meth:`Heartbeat.feed`);
between jobs a background thread pings the board every ``period_s``. When a ping fails, or no
answer came for ``timeout_s``, the watchdog calls ``on_dead`` (the controller's laser-off) at
once and stays dead: :meth:`Heartbeat.check` then raises DeviceError until :meth:`revive`
(a successful reconnect) is called.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from insitu.errors import DeviceError


class Heartbeat:
    """``ping``: asks the board for its status, raises on no answer (called with ``lock``
    held; skipped while someone else holds it — that someone feeds the watchdog itself).
    ``on_dead``: turns the laser off; must not raise. ``name``: for messages."""

    def __init__(self, name: str, ping: Callable[[], None], on_dead: Callable[[], None],
                 lock: threading.RLock, period_s: float = 0.25, timeout_s: float = 1.0):
        self.name, self._ping, self._on_dead, self._lock = name, ping, on_dead, lock
        self.period_s, self.timeout_s = float(period_s), float(timeout_s)
        self._last = time.monotonic()
        self._dead: str | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- called by the controller -------------------------------------------------------------
    def feed(self) -> None:
        """The board answered just now."""
        self._last = time.monotonic()

    def fail(self, reason: str) -> None:
        """The board did not answer: laser off, and dead until revived."""
        if self._dead is None:
            self._dead = reason
        self._on_dead()

    def revive(self) -> None:
        self._dead = None
        self.feed()

    @property
    def alive(self) -> bool:
        return self._dead is None and time.monotonic() - self._last <= self.timeout_s

    def check(self) -> None:
        """DeviceError unless the board answered within ``timeout_s`` (pings it once if the
        last answer is older): called before any command is sent to the laser."""
        if self._dead is None and time.monotonic() - self._last > self.timeout_s:
            self._beat()
        if self._dead is not None:
            raise DeviceError(f"{self.name}: no heartbeat from the controller ({self._dead}); "
                              "the laser is off and no command is sent until it answers again")

    # -- background thread --------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name=f"{self.name} heartbeat",
                                            daemon=True)
            self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5 * self.period_s + 1.0)
            self._thread = None

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            if self._lock.acquire(blocking=False):
                try:
                    self._beat_locked()
                finally:
                    self._lock.release()
            elif time.monotonic() - self._last > self.timeout_s:
                self.fail(f"no answer for {self.timeout_s:g} s")

    def _beat(self) -> None:
        with self._lock:
            self._beat_locked()

    def _beat_locked(self) -> None:
        if self._dead is not None:
            return
        try:
            self._ping()
        except Exception as e:                      # noqa: BLE001 — any failure is no answer
            self.fail(str(e))
        else:
            self.feed()
