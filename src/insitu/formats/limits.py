"""What every reader checks before it reads: the path is a regular file (not a FIFO, a device
such as ``/dev/zero``, a socket or a folder), no larger than the limit for its kind, and — for
the files of a folder format such as a recording — inside that folder once symlinks are
resolved. Image files are also limited in pixels, read from their header before decoding.

Limits (bytes unless said): JSON and CSV files 64 MiB (the largest calibration or job we write
is a few MB); point clouds 256 MiB (about 10 M points with intensity, line and quality); images
256 MiB and 64 Mpx (8192 x 8192; a camera frame is 5 Mpx); SVG and DXF drawings 16 MiB
(a logo is well under 1 MB; their parsers read about 1 MB a second).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from insitu.errors import FormatError

MiB = 1 << 20
MAX_JSON_BYTES = 64 * MiB
MAX_CLOUD_BYTES = 256 * MiB
MAX_IMAGE_BYTES = 256 * MiB
MAX_IMAGE_PIXELS = 64_000_000
MAX_DRAWING_BYTES = 16 * MiB

_KINDS = ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISDIR, "a folder"))


def _size(n: int) -> str:
    return f"{n / MiB:.1f} MiB" if n >= MiB else f"{n} bytes"


def _special(mode: int) -> str | None:
    return next((name for test, name in _KINDS if test(mode)),
                None if stat.S_ISREG(mode) else "not a regular file")


def check_file(path: str | Path, limit: int, what: str = "file", *, missing: str = "no such file",
               error: type[Exception] = FormatError) -> int:
    """The size in bytes of the regular file ``path`` (symlinks followed); ``error`` naming it
    when it is missing, special (FIFO, device, socket, folder) or larger than ``limit``."""
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise error(f"{path}: {missing}") from None
    except ValueError:                                   # a NUL in the name
        raise error(f"{path!r}: not a valid file name") from None
    except OSError as e:
        raise error(f"{path}: cannot read ({e.strerror or e})") from None
    kind = _special(st.st_mode)
    if kind is not None:
        raise error(f"{path}: {kind}, not a {what} (refused: only regular files are read)")
    if st.st_size > limit:
        raise error(f"{path}: {_size(st.st_size)}, larger than the {_size(limit)} limit for a "
                    f"{what}")
    return st.st_size


def read_limited(path: str | Path, limit: int, what: str = "file", *,
                 missing: str = "no such file", error: type[Exception] = FormatError) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them (see
    :func:`check_file`); the file is opened non-blocking and checked again once open, so a
    FIFO swapped in after the check neither blocks nor is read."""
    check_file(path, limit, what, missing=missing, error=error)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_BINARY", 0))
    except (FileNotFoundError, NotADirectoryError):
        raise error(f"{path}: {missing}") from None
    except OSError as e:
        raise error(f"{path}: cannot read ({e.strerror or e})") from None
    with os.fdopen(fd, "rb") as f:
        if _special(os.fstat(f.fileno()).st_mode) is not None:
            raise error(f"{path}: not a regular file (refused)")
        try:
            data = f.read(limit + 1)
        except OSError as e:
            raise error(f"{path}: cannot read ({e.strerror or e})") from None
    if len(data) > limit:
        raise error(f"{path}: larger than the {_size(limit)} limit for a {what}")
    return data


def check_inside(path: str | Path, folder: str | Path, what: str = "file",
                 error: type[Exception] = FormatError) -> Path:
    """``path`` with symlinks resolved; ``error`` when that leaves ``folder`` (a frame of a
    recording that is a symlink to elsewhere)."""
    try:
        real, root = Path(path).resolve(), Path(folder).resolve()
    except (OSError, RuntimeError, ValueError) as e:       # a symlink loop, a NUL
        raise error(f"{path}: cannot resolve the path ({e})") from None
    if not real.is_relative_to(root):
        raise error(f"{path}: the {what} leads out of {folder} (a symlink to {real}; refused)")
    return real
