"""Long work off the GUI thread: a :class:`Task` runs a function of (progress, cancel, frame)
on a Python thread and reports back through Qt signals, which Qt delivers on the GUI thread.
A failure becomes one line (InsituError's message); the window never freezes."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import numpy as np
from PySide6.QtCore import QObject, Signal

from insitu.errors import InsituError
from insitu.services import Cancelled, ScanFrame

log = logging.getLogger(__name__)
FRAME_INTERVAL_S = 0.05


class Task(QObject):
    """``fn(progress, cancel, on_frame) -> result``. Signals: ``progress(done, total)``,
    ``frame(image, centres, points)`` (at most every 50 ms; ``points`` gathers every frame's
    since the last), ``done(result)``, ``failed(message, cancelled)``, then ``ended``.
    ``error``: the exception behind ``failed`` (e.g. a ScanInterrupted with its partial
    result), readable until ``ended``."""

    progress = Signal(int, int)
    frame = Signal(object, object, object)
    done = Signal(object)
    failed = Signal(str, bool)
    ended = Signal()

    def __init__(self, name: str, fn: Callable, parent: QObject | None = None):
        super().__init__(parent)
        self.name, self.fn = name, fn
        self.cancel = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name=f"insitu-{name}", daemon=True)
        self._points: list[np.ndarray] = []
        self._last_frame = 0.0

    def start(self) -> None:
        self.thread.start()

    def _on_frame(self, f: ScanFrame) -> None:
        self._points.append(f.points)
        now = time.perf_counter()
        if now - self._last_frame >= FRAME_INTERVAL_S or f.index + 1 == f.total:
            pts = np.concatenate(self._points) if self._points else np.zeros((0, 3))
            self._points, self._last_frame = [], now
            self.frame.emit(f.image, f.centres, pts)

    def _run(self) -> None:
        try:
            result = self.fn(self.progress.emit, self.cancel, self._on_frame)
        except Cancelled as e:
            self.error = e
            self.failed.emit(str(e), True)
        except InsituError as e:
            self.error = e
            self.failed.emit(str(e), False)
        except Exception as e:                      # noqa: BLE001 — shown, not swallowed
            self.error = e
            log.exception("%s failed", self.name)
            self.failed.emit(f"{self.name}: unexpected error: {type(e).__name__}: {e}", False)
        else:
            self.done.emit(result)
        self.ended.emit()


class TaskRunner(QObject):
    """At most one task of each name at a time; keeps them alive until they end."""

    busy_changed = Signal(str, bool)

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self.tasks: dict[str, Task] = {}

    def running(self, name: str) -> bool:
        return name in self.tasks

    def start(self, name: str, fn: Callable, on_done: Callable | None = None,
              on_failed: Callable[[str, bool], None] | None = None) -> Task | None:
        """Run ``fn`` as task ``name``; None if one of that name is still running."""
        if name in self.tasks:
            return None
        task = Task(name, fn, self)
        if on_done:
            task.done.connect(on_done)
        if on_failed:
            task.failed.connect(on_failed)
        task.ended.connect(lambda: self._ended(name))
        self.tasks[name] = task
        self.busy_changed.emit(name, True)
        task.start()
        return task

    def cancel(self, name: str) -> None:
        if name in self.tasks:
            self.tasks[name].cancel.set()

    def _ended(self, name: str) -> None:
        task = self.tasks.pop(name, None)
        if task is not None:
            task.deleteLater()
        self.busy_changed.emit(name, False)

    def wait_all(self, timeout_s: float = 10.0) -> None:
        """Cancel every task and wait for its thread (closing the window)."""
        for task in list(self.tasks.values()):
            task.cancel.set()
            task.thread.join(timeout_s)
