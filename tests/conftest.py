"""Shared by every tier (unit, gui, hardware): the simulated boards import as ``fakes``
(``tests/fakes``), the recordings are in ``tests/data``."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
