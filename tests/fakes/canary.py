"""A native library that proves whether it was loaded: its constructor (run by the dynamic
loader the moment the library is loaded, before any function is called) creates a file."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

SOURCE = r"""
#include <stdio.h>
__attribute__((constructor)) static void loaded(void) {
    FILE *f = fopen(MARKER, "w");
    if (f) { fputs("loaded\n", f); fclose(f); }
}
"""


def build(folder: Path, name: str = "libcanary.so") -> tuple[Path, Path]:
    """Compile the canary into ``folder``; returns (library, the file its loading creates)."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise RuntimeError("no C compiler (install gcc and libc6-dev: scripts/setup.sh does)")
    src, lib, marker = folder / "canary.c", folder / name, folder / f"{name}.loaded"
    src.write_text(SOURCE)
    subprocess.run([cc, "-shared", "-fPIC", "-o", str(lib), f'-DMARKER="{marker}"', str(src)],
                   check=True, capture_output=True)
    return lib, marker
