"""Builds the fake RTC library (fake_rtc.c) with the system C compiler and reads its records."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np

SOURCE = Path(__file__).with_name("fake_rtc.c")


def build(folder: Path) -> Path:
    """Compile the fake into ``folder``; returns the .so path."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (install gcc and libc6-dev: scripts/setup.sh does)")
    out = folder / "libfake_rtc.so"
    subprocess.run([cc, "-shared", "-fPIC", "-O1", "-o", str(out), str(SOURCE), "-lpthread"],
                   check=True, capture_output=True)
    return out


class FakeBoard:
    """Test-side handle on the loaded fake (the same library object ctypes gives the
    controller: CDLL caches nothing, but dlopen returns the same handle for the same path)."""

    def __init__(self, path: Path):
        self.lib = ctypes.CDLL(str(path))
        self.lib.fake_calls.restype = ctypes.c_char_p
        self.lib.fake_marks.restype = ctypes.c_char_p
        self.lib.fake_fail_after.argtypes = [ctypes.c_long]
        self.lib.fake_port.restype = ctypes.c_uint

    def reset(self) -> None:
        self.lib.fake_reset()

    def calls(self) -> list[str]:
        return self.lib.fake_calls().decode().splitlines()

    def marks(self) -> np.ndarray:
        """(M, 7) int: list run, from (x, y, z), to (x, y, z) bits of each segment marked."""
        rows = [list(map(int, s.split())) for s in self.lib.fake_marks().decode().splitlines()]
        return np.array(rows, dtype=np.int64).reshape(-1, 7)

    def fail_after(self, n: int) -> None:
        self.lib.fake_fail_after(n)

    def set_step(self, n: int) -> None:
        self.lib.fake_set_step(n)

    @property
    def laser_enabled(self) -> bool:
        return bool(self.lib.fake_laser_enabled())

    @property
    def port(self) -> int:
        return int(self.lib.fake_port())

    @property
    def dead(self) -> bool:
        return bool(self.lib.fake_dead())
