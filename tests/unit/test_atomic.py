"""Atomic files and folders: a write replaces whole or not at all, and leaves no temporary."""

from __future__ import annotations

import pytest

from insitu.errors import FormatError
from insitu.formats import atomic
from insitu.formats.atomic import atomic_folder, atomic_write_bytes, atomic_write_text

# -- atomic files and folders ------------------------------------------------------------

def test_atomic_write_text_replaces_and_leaves_no_temp(tmp_path):
    target = tmp_path / "a.json"
    atomic_write_text(target, "one")
    atomic_write_text(target, "two")
    atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01")
    assert target.read_text() == "two" and (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.bin"]


def test_atomic_write_text_leaves_no_temp_file_on_error(tmp_path, monkeypatch):
    target = tmp_path / "a.json"
    target.write_text("old")

    def fail(*args):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(atomic.os, "replace", fail)
    with pytest.raises(FormatError, match="a.json: cannot write .No space left"):
        atomic_write_text(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]


def test_atomic_write_needs_the_folder(tmp_path):
    with pytest.raises(FormatError, match="missing"):
        atomic_write_text(tmp_path / "missing" / "a.json", "x")


def test_atomic_folder(tmp_path):
    with atomic_folder(tmp_path / "out") as tmp:
        assert tmp.name.startswith(".out.tmp-") and tmp.parent == tmp_path
        (tmp / "x").write_text("1")
        assert not (tmp_path / "out").exists()
    assert (tmp_path / "out" / "x").read_text() == "1"
    with pytest.raises(ValueError):
        with atomic_folder(tmp_path / "out") as tmp:
            (tmp / "y").write_text("2")
            raise ValueError
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["x"]
    with atomic_folder(tmp_path / "out") as tmp:
        (tmp / "z").write_text("3")
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["z"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
