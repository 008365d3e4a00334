"""Folders made once per test run and shared by pytest-xdist's workers: the recordings and
fitted calibrations the session fixtures of tests/conftest.py and tests/integration/conftest.py
return. ``INSITU_TEST_SHARED`` names a folder for them that outlives one pytest run
(scripts/test.sh: both tiers fit the height calibration once)."""

import fcntl
import os
import shutil
from collections.abc import Callable
from pathlib import Path


def shared(tmp_path_factory, name: str, make: Callable[[Path], None]) -> Path:
    """The folder ``name`` of this test run, filled by ``make(folder)`` once: the workers of
    pytest-xdist share it (the first makes it, the others wait for it under a file lock)."""
    if os.environ.get("INSITU_TEST_SHARED"):
        root = Path(os.environ["INSITU_TEST_SHARED"])
    else:
        root = tmp_path_factory.getbasetemp()
        if "PYTEST_XDIST_WORKER" in os.environ:
            root = root.parent                          # the run's, above each worker's
        root = root / "shared"
    folder = root / name
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(folder.parent / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not folder.is_dir():
            partial = folder.with_name(f"{name}.partial")
            shutil.rmtree(partial, ignore_errors=True)
            partial.mkdir()
            make(partial)
            partial.rename(folder)
    return folder
