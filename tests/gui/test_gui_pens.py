"""Pens in the application (pytest-qt, offscreen): editing a pen in the editor the Mark dock
opens, choosing it for a placement in the Place dock, the planned job carrying it, its
colour in the view, undo, a refused edit and the project keeping the pens."""

import test_gui_workflow as workflow
from PySide6.QtCore import Qt

from insitu.formats.project import read_project
from insitu.marking import PROJECTIONS, Placement

WAIT_MS, place, scan_recording = workflow.WAIT_MS, workflow.place, workflow.scan_recording
window = workflow.window     # the same fixture


def _planned(qtbot, w):
    qtbot.waitUntil(lambda: w.session.plans and w.session.plans[0].plan is not None
                    and not w.runner.running("plan") and not w._plan_timer.isActive(),
                    timeout=WAIT_MS)
    return w.mark_panel.job()


def _cell(editor, pen, header):
    from insitu.ui.qt.pens_panel import COLUMNS
    row = editor.session.pens.names.index(pen)
    col = [h for h, _ in COLUMNS].index(header)
    return editor.table.item(row, col)


def test_edit_a_pen_choose_it_for_a_placement_and_mark_with_it(qtbot, window, tmp_path):
    w, s = window, window.session
    scan_recording(qtbot, w)
    place(qtbot, w)
    job = _planned(qtbot, w)
    assert job.pens() == {"mark": list(range(len(job.paths)))}       # the default pen
    qtbot.mouseClick(w.mark_panel.pens_row.button, Qt.LeftButton)
    editor = w.mark_panel.pens_row.editor
    assert editor.isVisible() and editor.table.rowCount() == 4
    _cell(editor, "deep", "Passes").setText("3")                       # typed in the table
    assert s.pens.pen("deep").passes == 3
    _cell(editor, "deep", "Power %").setText("150")                    # refused, one line
    assert editor.error.text() == "pens: pen 'deep'.power_pct: 150 is outside 0 … 100 %"
    assert s.pens.pen("deep").power_pct == 80.0 and _cell(editor, "deep", "Power %").text() == "80"
    chooser = w.place_panel.pen_chooser
    chooser.setCurrentIndex(chooser.findData("deep"))                  # the Place dock's pen
    assert s.current().pen == "deep"
    job = _planned(qtbot, w)
    assert job.pens() == {"deep": list(range(len(job.paths)))}
    assert job.path_passes(0) == 3 and job.path_laser(0).power_pct == 80.0
    assert w.view.renderer.lines["projected #ff8000"][0].count > 0     # drawn in its colour
    assert "deep (80 %" in w.mark_panel.pens_row.label.text()
    assert w.save(tmp_path / "p.insitu.json")
    back = read_project(tmp_path / "p.insitu.json", Placement, PROJECTIONS)
    assert back.pens == s.pens and back.placements[0].pen == "deep"
    w.undo_action.trigger()                                            # the pen change undone
    assert s.current().pen is None and chooser.currentData() == "mark"
    job = _planned(qtbot, w)
    assert list(job.pens()) == ["mark"]
    assert w.view.renderer.lines["projected #ff8000"][0].count == 0


def test_renaming_a_pen_keeps_the_placements_on_it(qtbot, window):
    w, s = window, window.session
    scan_recording(qtbot, w)
    place(qtbot, w)
    w.place_panel.pen_chooser.setCurrentIndex(w.place_panel.pen_chooser.findData("fine"))
    editor = w.mark_panel.pens_row.open_editor()
    _cell(editor, "fine", "Name").setText("hairline")
    assert "hairline" in s.pens.names and s.current().pen == "hairline"
    s.update_selected(width_mm=11.0)
    editor.table.setCurrentCell(s.pens.names.index("hairline"), 0)
    editor.remove_button.click()
    assert "hairline" not in s.pens.names and s.current().pen is None
    w.undo_action.trigger()                 # back to the width before: its pen is gone too
    assert s.current().width_mm == 12.0 and s.current().pen is None
