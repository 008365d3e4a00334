"""The gui tier's station file: its own, empty until a test allows a library."""

import pytest

from fakes.station import isolated_station


@pytest.fixture(scope="session", autouse=True)
def station_file(tmp_path_factory):
    yield from isolated_station(tmp_path_factory)


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_teardown(item):
    """A window a test left with unsaved changes would ask Save / Discard / Cancel when
    pytest-qt closes it (its own teardown hook, after this one) — a modal box nobody answers
    offscreen. Every main window is marked saved first."""
    from PySide6.QtWidgets import QApplication

    from insitu.ui.qt.main_window import MainWindow
    for w in QApplication.topLevelWidgets():
        if isinstance(w, MainWindow):
            w.saved.mark_clean()
    return (yield)
