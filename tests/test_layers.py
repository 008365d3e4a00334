"""Only insitu.ui may import Qt or OpenGL, and nothing in the core imports insitu.ui."""

import ast
from pathlib import Path

import insitu

PKG = Path(insitu.__file__).parent
FORBIDDEN = ("PySide6", "OpenGL", "insitu.ui")


def _imports(path: Path):
    tree = ast.parse(path.read_text(), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module


def test_core_does_not_import_qt_or_opengl():
    offenders = []
    core = [p for p in PKG.rglob("*.py") if "ui" not in p.relative_to(PKG).parts[:1]]
    assert len(core) > 10
    for path in core:
        for name in _imports(path):
            if name.split(".")[0] in FORBIDDEN or name.startswith("insitu.ui"):
                offenders.append(f"{path.relative_to(PKG)} imports {name}")
    assert not offenders, offenders
