"""A benchmark script of ``benchmarks/`` loaded as a module, for the tests that hold its rules
(scoring, draws) to account."""

import functools
import importlib.util
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@functools.lru_cache(maxsize=None)
def benchmark(name: str):
    """The module of ``benchmarks/<name>.py`` (loaded once)."""
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
