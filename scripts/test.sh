#!/usr/bin/env bash
# The README's test command: ruff and the layer contracts, then the tests in two tiers, each on
# every core (pytest-xdist):
#   core  tests/unit, tests/integration — the GUI packages made unimportable (INSITU_TEST_NO_QT),
#         as where insitu is installed without its gui extra;
#   gui   tests/gui — offscreen Qt, OpenGL under Xvfb.
# Extra arguments go to one pytest run instead of the tiers (Qt importable, under Xvfb), e.g.
# scripts/test.sh tests/unit/test_job.py -x, or INSITU_RIG=rig.json scripts/test.sh -m hardware.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/setup.sh"
cd "$ROOT"
export QT_QPA_PLATFORM="${QT_QPA_PLATFORM:-offscreen}"
# the tests' files in memory where there is tmpfs (journals and mark logs fsync every record),
# under a short folder (commands wrap the paths they print at 80 columns)
if [ -z "${TMPDIR:-}" ] && [ -d /dev/shm ] && [ -w /dev/shm ]; then export TMPDIR=/dev/shm; fi
BASETEMP="$(mktemp -d "${TMPDIR:-/tmp}/t.XXXX")"
trap 'rm -rf "$BASETEMP"' EXIT
# the recordings and fitted calibrations of the session fixtures made once for both tiers
export INSITU_TEST_SHARED="$BASETEMP/shared"
# bytecode written: each module (and each test file's assertion rewrite) compiled once, not in
# every worker, tier and command the tests start
unset PYTHONDONTWRITEBYTECODE
ruff check src tests benchmarks patterns
lint-imports pyproject.toml
XVFB=(xvfb-run -a -s "-screen 0 1280x1024x24")
if (($#)); then
    "${XVFB[@]}" python -m pytest --basetemp="$BASETEMP/run" "$@"
    exit
fi
# the long tests first: the short ones fill the workers' ends; each test file runs on one
# worker, its tests one after the other (its module fixtures made once: xdist 3.8's loadgroup
# does not group under pytest 9.2, whose node ids it cannot suffix)
XDIST=(-n auto --dist loadfile --durations=15)
INSITU_TEST_NO_QT=1 python -m pytest -p no:pytest-qt "${XDIST[@]}" --basetemp="$BASETEMP/core" \
    tests/integration tests/unit
"${XVFB[@]}" python -m pytest "${XDIST[@]}" --basetemp="$BASETEMP/gui" tests/gui
