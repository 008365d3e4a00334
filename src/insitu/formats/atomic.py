"""Nothing lost: files and folders are written under a hidden temporary name beside the target
and renamed onto it, so a reader sees either the old version or the complete new one."""

from __future__ import annotations

import os
import secrets
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from insitu.errors import FormatError


def _umask() -> int:
    """The process umask, read without changing it (Linux); 0o022 elsewhere."""
    with suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    return 0o022


_NEW_FILE_MODE = 0o666 & ~_umask()


def _check_parent(path: Path) -> None:
    if path.name in ("", ".", ".."):
        raise FormatError(f"{path}: not a file or folder name")
    if not path.parent.is_dir():
        raise FormatError(f"{path}: folder {path.parent} does not exist")


def _fsync_dir(folder: Path) -> None:
    """Make a rename in ``folder`` durable (POSIX; a no-op where directories can't be opened)."""
    with suppress(OSError, AttributeError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextmanager
def atomic_file(path: str | Path, suffix: str = ".tmp") -> Iterator[Path]:
    """A hidden temporary path beside ``path`` to write the new file to (by name, e.g. a
    library that only writes paths; ``suffix``: its ending, e.g. ".ply" for one that picks
    the format by it). On normal exit it is fsynced, given ``path``'s mode (a new file: the
    umask's) and renamed onto ``path``; on an exception it is removed and ``path`` is left as
    it was. FormatError if the folder does not exist or an OS call fails."""
    path = Path(path)
    _check_parent(path)
    try:
        mode = path.stat().st_mode & 0o7777
    except OSError:
        mode = _NEW_FILE_MODE
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix)
        os.close(fd)
    except OSError as e:
        raise FormatError(f"{path}: cannot write ({e.strerror or e})") from e
    try:
        yield Path(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        with suppress(OSError):
            os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException as e:
        with suppress(OSError):
            os.unlink(tmp)
        if isinstance(e, OSError):
            raise FormatError(f"{path}: cannot write ({e.strerror or e})") from e
        raise
    _fsync_dir(path.parent)


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through :func:`atomic_file` (temp file, fsync, rename)."""
    with atomic_file(path) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | Path, text: str) -> None:
    """:func:`atomic_write_bytes` of ``text`` encoded as UTF-8 (newlines written as given)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with suppress(OSError):
            path.unlink()


@contextmanager
def atomic_folder(path: str | Path) -> Iterator[Path]:
    """Build a folder under a hidden temporary name and put it at ``path`` when done.

    Yields the temp sibling ``.<name>.tmp-<random>``. On normal exit it replaces ``path`` (an
    existing ``path`` is moved aside, the new folder renamed in, the old one deleted). On an
    exception the temp folder is deleted and ``path`` is untouched.
    """
    path = Path(path)
    _check_parent(path)
    tmp = path.parent / f".{path.name}.tmp-{secrets.token_hex(6)}"
    try:
        tmp.mkdir()
    except OSError as e:
        raise FormatError(f"{path}: cannot create a folder beside it ({e.strerror or e})") from e
    try:
        yield tmp
        _swap_in(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _swap_in(tmp: Path, path: Path) -> None:
    if not (path.exists() or path.is_symlink()):
        try:
            os.rename(tmp, path)
        except OSError as e:
            raise FormatError(f"{path}: cannot rename the new folder into place "
                              f"({e.strerror or e})") from e
        _fsync_dir(path.parent)
        return
    old = path.parent / f".{path.name}.old-{secrets.token_hex(6)}"
    try:
        os.rename(path, old)
    except OSError as e:
        raise FormatError(f"{path}: cannot move the existing one aside ({e.strerror or e})") from e
    try:
        os.rename(tmp, path)
    except BaseException as e:
        os.rename(old, path)
        if isinstance(e, OSError):
            raise FormatError(f"{path}: cannot rename the new folder into place "
                              f"({e.strerror or e})") from e
        raise
    _fsync_dir(path.parent)
    _remove(old)
