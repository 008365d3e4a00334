"""Unsaved changes: what a project file keeps of the session (placements, cloud, calibration
and rig choices, scan settings), compared with what it was when last saved or opened."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


class SavedState:
    """``state()`` returns a dict of what a project keeps; values are compared with ``==``
    except the ``cloud`` (an array-holding object), compared by identity. :meth:`mark_clean`
    after saving, opening or starting a new project; :meth:`dirty` says whether anything
    differs since."""

    def __init__(self, state: Callable[[], dict[str, Any]]):
        self._state = state
        self._clean: dict[str, Any] = state()

    def mark_clean(self) -> None:
        self._clean = self._state()

    def changes(self) -> list[str]:
        """The names of what changed since the last :meth:`mark_clean`."""
        now, then = self._state(), self._clean
        return [k for k in now
                if (now[k] is not then.get(k) if k == "cloud" else now[k] != then.get(k))]

    def dirty(self) -> bool:
        return bool(self.changes())
