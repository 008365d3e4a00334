"""The Mark dock asks how to go on with an unfinished job: the three choices for a cut path,
resume or start over without one (pytest-qt, offscreen)."""

import pytest
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication, QMessageBox, QWidget

from insitu.marking import JournalSummary
from insitu.ui.qt.mark_panel import MarkPanel


def answer(qtbot, summary, button_text):
    """Open the question, click ``button_text`` in it; returns ask_resume's result and the
    buttons it offered."""
    parent = QWidget()
    qtbot.addWidget(parent)
    offered = []

    def click():
        box = next(w for w in QApplication.topLevelWidgets()
                   if isinstance(w, QMessageBox) and w.isVisible())
        offered.extend(b.text() for b in box.buttons())
        next(b for b in box.buttons() if b.text() == button_text).click()

    QTimer.singleShot(50, click)
    return MarkPanel.ask_resume(parent, summary), offered


@pytest.mark.parametrize("text, expected", [
    ("Mark the cut path again", {"resume": True, "cut_path": "remark"}),
    ("Skip the cut path", {"resume": True, "cut_path": "skip"}),
    ("Continue the cut path", {"resume": True, "cut_path": "continue"}),
    ("Start over", {"restart": True}), ("Cancel", None)])
def test_a_cut_path_offers_the_three_choices(qtbot, text, expected):
    s = JournalSummary("0" * 64, 10, done={0, 1, 2}, cut=3, cut_position=4,
                       state="interrupted")
    got, offered = answer(qtbot, s, text)
    assert got == expected
    assert {"Mark the cut path again", "Skip the cut path", "Continue the cut path",
            "Start over"} <= set(offered)


def test_without_a_cut_path_it_offers_resume_or_start_over(qtbot):
    s = JournalSummary("0" * 64, 10, done={0, 1}, state="cancelled")
    got, offered = answer(qtbot, s, "Resume")
    assert got == {"resume": True} and "Skip the cut path" not in offered
    assert MarkPanel.ask_resume(None, None) == {}
