#!/usr/bin/env bash
# The unit tests without the GUI packages: .venv-core holds insitu[test] only (no PySide6,
# PyOpenGL, pytest-qt), so a unit test that needs Qt fails here. Extra arguments go to pytest.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
INSITU_VENV="$ROOT/.venv-core" INSITU_EXTRAS=test source "$ROOT/scripts/setup.sh"
cd "$ROOT"
if python -c "import PySide6" 2>/dev/null || python -c "import OpenGL" 2>/dev/null; then
    echo "test-core: $ROOT/.venv-core has a GUI package; remove the folder and run again" >&2
    exit 1
fi
insitu --help >/dev/null
exec python -m pytest tests/unit "$@"
