"""Only insitu.ui.qt may import Qt or OpenGL, nothing in the core imports insitu.ui, and the
unit and integration tests run without the GUI packages."""

import ast
from pathlib import Path

import insitu

PKG = Path(insitu.__file__).parent
FORBIDDEN = ("PySide6", "OpenGL", "insitu.ui")


# the one lazy import of the GUI, inside the `insitu gui` command (as pyproject's ignore_imports)
LAZY_GUI = {("cli/main.py", "insitu.ui.qt.app")}
GUI_ONLY = ("PySide6", "OpenGL", "pytestqt", "insitu.ui.qt")


def _imports(path: Path, top_level_only: bool = False):
    tree = ast.parse(path.read_text(), str(path))
    for node in (tree.body if top_level_only else ast.walk(tree)):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module


def test_core_does_not_import_qt_or_opengl():
    offenders = []
    core = [p for p in PKG.rglob("*.py") if "ui" not in p.relative_to(PKG).parts[:1]]
    assert len(core) > 10
    for path in core:
        rel = path.relative_to(PKG).as_posix()
        top = set(_imports(path, top_level_only=True))
        for name in _imports(path):
            lazy_gui = (rel, name) in LAZY_GUI and name not in top
            if (name.split(".")[0] in FORBIDDEN or name.startswith("insitu.ui")) and not lazy_gui:
                offenders.append(f"{rel} imports {name}")
    assert not offenders, offenders


def _gui_imports(paths) -> list[str]:
    return [f"{path.name} imports {name}" for path in paths for name in _imports(path)
            if name.startswith(GUI_ONLY)]


def test_the_gui_models_do_not_import_qt():
    models = sorted((PKG / "ui" / "model").glob("*.py"))
    assert len(models) >= 4
    assert not _gui_imports(models)


def test_the_unit_tests_need_no_gui_package():
    """tests/unit and tests/integration run with the GUI packages unimportable (scripts/test.sh's
    core tier): no Qt, no qtbot."""
    tiers = Path(__file__).parents[1]
    tests = sorted([*(tiers / "unit").glob("*.py"), *(tiers / "integration").glob("*.py")])
    assert len(tests) > 30
    offenders = _gui_imports(tests)
    offenders += [f"{p.name} uses qtbot" for p in tests if "qtbot" in p.read_text()
                  and p.name != Path(__file__).name]
    assert not offenders, offenders
