"""The serial counter: a small JSON file that hands out each serial number once.

    {"format": "insitu-serial-counter/1", "next": 43,
     "issued": [{"serial": 42, "job": "part.json", "digest": "9f…", "time": "2026-…+00:00"}]}

``next`` is the serial the next job takes; ``issued`` keeps the last :data:`KEEP` serials
handed out (newest last) with the job that took them. Serials are taken under an exclusive
lock (``fcntl.flock`` on ``COUNTER.lock`` beside it — the counter itself is replaced on every
write, so it cannot carry the lock) and written atomically with fsync before the caller writes
its job, so two processes never take the same serial and a serial once taken is never handed
out again, whatever happens to its job (a fault, an abort, a crash before the job is written).

    with locked("serial.counter.json") as c:
        serial = c.next
        ...                                   # plan the job with it
        c.issue(serial, job="part.json", digest=job.digest())
"""

from __future__ import annotations

import errno
import fcntl
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import datetime
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.validation import dump_json, read_json, validation_message

COUNTER_FORMAT = "insitu-serial-counter/1"
KEEP = 20                    # issued serials kept in the file
MAX_SERIAL = 10 ** 12        # a serial is a part number, not an arbitrary integer
LOCK_TIMEOUT_S = 30.0
Serial = Annotated[int, Field(ge=0, le=MAX_SERIAL, strict=True)]


class Issued(BaseModel):
    """One serial handed out: to which job (its file name as given and digest) and when."""

    model_config = ConfigDict(extra="allow", frozen=True)
    serial: Serial
    job: str | None = None
    digest: str | None = None
    time: str


class Counter(BaseModel):
    """The counter file's content."""

    model_config = ConfigDict(extra="allow", frozen=True)
    format: Literal["insitu-serial-counter/1"] = COUNTER_FORMAT
    next: Serial
    issued: list[Issued] = []

    @property
    def last(self) -> int | None:
        """The highest serial issued (None: none kept)."""
        return max((i.serial for i in self.issued), default=None)


def read_counter(path: str | Path) -> Counter:
    """Read and validate a counter; FormatError ``file: field: problem``."""
    path = Path(path)
    data = read_json(path, missing="no such serial counter (a first serial creates one)")
    if not isinstance(data, dict):
        raise FormatError(f"{path}: expected a JSON object (a serial counter), got "
                          f"{type(data).__name__}")
    try:
        return Counter.model_validate(data)
    except ValidationError as e:
        raise FormatError(validation_message(path, e)) from None


def write_counter(path: str | Path, counter: Counter) -> None:
    """Write ``counter`` atomically (fsynced temporary file renamed onto ``path``)."""
    atomic_write_text(path, dump_json(counter.model_dump(mode="json", exclude_none=True)) + "\n")


def lock_path(path: str | Path) -> Path:
    """The lock file of the counter at ``path``."""
    path = Path(path)
    return path.with_name(path.name + ".lock")


class LockedCounter:
    """A counter held under its lock (see :func:`locked`): read it, create it, take serials."""

    def __init__(self, path: Path):
        self.path = path
        self.counter = read_counter(path) if path.exists() else None

    @property
    def next(self) -> int:
        """The serial the next job takes; FormatError when there is no counter yet."""
        if self.counter is None:
            read_counter(self.path)          # raises: no such serial counter
        return self.counter.next

    def create(self, start: int) -> None:
        """A new counter whose first serial is ``start``; FormatError if one exists."""
        if self.counter is not None:
            raise FormatError(f"{self.path}: a serial counter exists (next {self.counter.next}); "
                              "give no first serial, or change it with insitu serial set")
        self._write(Counter(next=_serial(start, "serial start", "serial_start")))

    def issue(self, serial: int, job: str | None = None, digest: str | None = None) -> None:
        """Hand out ``serial`` (it must be :attr:`next`): the counter moves on to the next one
        and keeps the record; written and fsynced before this returns."""
        if serial != self.next:
            raise FormatError(f"{self.path}: serial {serial} is not the next one ({self.next})")
        rec = Issued(serial=serial, job=job, digest=digest,
                     time=datetime.now().astimezone().isoformat(timespec="seconds"))
        c = self.counter
        self._write(c.model_copy(update={"next": serial + 1,
                                         "issued": [*c.issued, rec][-KEEP:]}))

    def set_next(self, value: int, force: bool = False) -> None:
        """Make ``value`` the next serial (creating the counter if there is none). Going back
        to a serial already issued would hand it out twice: refused unless ``force``."""
        value = _serial(value, "next")
        if self.counter is None:
            self._write(Counter(next=value))
            return
        last = self.counter.last
        if last is not None and value <= last and not force:
            raise FormatError(f"{self.path}: serial {last} was issued already; next {value} would "
                              "hand out serials twice (force it to do it anyway)")
        self._write(self.counter.model_copy(update={"next": value}))

    def _write(self, counter: Counter) -> None:
        write_counter(self.path, counter)
        self.counter = counter


def _serial(value: int, what: str, field: str | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_SERIAL:
        raise FormatError(f"{what} {value!r}: expected a whole number 0 … {MAX_SERIAL}",
                          field=field)
    return value


@contextmanager
def locked(path: str | Path, timeout_s: float = LOCK_TIMEOUT_S) -> Iterator[LockedCounter]:
    """Hold the counter at ``path`` exclusively (against other processes and threads) for the
    ``with`` block; FormatError when its folder is missing or another process holds it longer
    than ``timeout_s``."""
    path = Path(path)
    if not path.parent.is_dir():
        raise FormatError(f"{path}: folder {path.parent} does not exist")
    try:
        fd = os.open(lock_path(path), os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as e:
        raise FormatError(f"{lock_path(path)}: cannot open the lock file ({e.strerror})") from None
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError as e:
                if e.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                    raise FormatError(f"{lock_path(path)}: cannot lock ({e.strerror})") from None
                if time.monotonic() > deadline:
                    raise FormatError(f"{path}: held by another process for {timeout_s:g} s "
                                      "(another insitu planning a job?)") from None
                time.sleep(0.01)
        yield LockedCounter(path)
    finally:
        os.close(fd)                          # closing the descriptor releases the lock
