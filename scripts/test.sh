#!/usr/bin/env bash
# All tests: unit, GUI offscreen and OpenGL under Xvfb. Extra arguments go to pytest.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/setup.sh"
cd "$ROOT"
export QT_QPA_PLATFORM="${QT_QPA_PLATFORM:-offscreen}"
lint-imports pyproject.toml
python -m pyflakes src tests benchmarks patterns
exec xvfb-run -a -s "-screen 0 1280x1024x24" python -m pytest "$@"
