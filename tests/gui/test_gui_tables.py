"""The GUI reads the tables: the Place dock's projection modes and its file filter, and drag
and drop of every pattern file type."""

from PySide6.QtCore import QSettings, Qt

from insitu.marking import PROJECTIONS
from insitu.patterns import FILE_SUFFIXES
from insitu.ui.qt.main_window import MainWindow
from insitu.ui.qt.place_panel import PATTERN_FILES, short_name


def test_the_place_dock_offers_the_tables_choices(qtbot, tmp_path):
    w = MainWindow(QSettings(str(tmp_path / "settings.ini"), QSettings.IniFormat))
    qtbot.addWidget(w)
    combo = w.place_panel.ui.modeCombo
    assert [combo.itemText(i) for i in range(combo.count())] == list(PROJECTIONS)
    assert [combo.itemData(i, Qt.ItemDataRole.ToolTipRole) for i in range(combo.count())] == \
        [m.description for m in PROJECTIONS.values()]
    assert PATTERN_FILES[PATTERN_FILES.index("(") + 1:-1].split() == \
        ["*" + s for s in FILE_SUFFIXES]
    assert short_name('qr:"a"') == 'qr:"a"' and short_name("/x/logo.svg") == "logo.svg"
    w.runner.wait_all()
