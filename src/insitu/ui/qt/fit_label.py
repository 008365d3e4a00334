"""A one-line label whose text never widens its layout: cut with "…" to the width it is given
(at the end, or in the middle for a path), the whole text in its tooltip whenever it is cut."""

from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QLabel, QSizePolicy


class FitLabel(QLabel):
    """``elide``: Qt.ElideRight (messages) or Qt.ElideMiddle (paths). :meth:`full_text` is
    what was set; ``text()`` what fits."""

    def __init__(self, text: str = "", elide=Qt.TextElideMode.ElideRight, parent=None):
        super().__init__(parent)
        self._full = ""
        self._tip = ""
        self.elide = elide
        self.setSizePolicy(QSizePolicy.Policy.Ignored, QSizePolicy.Policy.Preferred)
        self.setMinimumWidth(40)
        self.set_text(text)

    def full_text(self) -> str:
        return self._full

    def set_text(self, text: str, tooltip: str = "") -> None:
        """Show ``text`` (one line); ``tooltip``: said in the tooltip (default: the text
        when it does not fit)."""
        self._full, self._tip = " ".join(str(text).split()), tooltip
        self._fit()

    def resizeEvent(self, e) -> None:
        super().resizeEvent(e)
        self._fit()

    def _fit(self) -> None:
        width = max(self.width() - 4, 10)
        shown = self.fontMetrics().elidedText(self._full, self.elide, width)
        super().setText(shown)
        self.setToolTip(self._tip or (self._full if shown != self._full else ""))
