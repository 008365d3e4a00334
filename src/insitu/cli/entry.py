"""The ``insitu`` command's entry point: ``insitu pattern …`` starts with only what patterns
need (the other commands bring SciPy, Open3D and the services: seconds of imports); every
other command runs through :mod:`insitu.cli.main`, the one root of all commands."""

from __future__ import annotations

import sys


def main() -> None:
    if sys.argv[1:2] == ["pattern"]:
        from insitu.cli.pattern import standalone

        standalone()
        return
    from insitu.cli.main import main as run_all

    run_all()
