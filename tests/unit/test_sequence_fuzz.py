"""Fuzzing a recorded sequence's sequence.json: nothing but a one-line FormatError, ever."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import cv2
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from insitu.errors import FormatError
from insitu.formats.sequence import Sequence
from tiny_sequence import CAMERA, HEAD, H, W, line

# -- fuzz: arbitrary sequence.json never raises anything but FormatError -------------------

_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                               max_size=4),
    max_leaves=12)
_KEYS = ["format", "kind", "camera", "scan_head", "frames", "checkerboard", "width", "K", "dist",
         "R", "t", "lens", "line", "spot", "file", "start", "end", "plate_z_mm", "z_range_mm"]


def _valid() -> dict:
    return {"format": "insitu-sequence/1", "kind": "scan",
            "camera": {**CAMERA, "R": np.eye(3).tolist()}, "scan_head": HEAD,
            "frames": [{"file": "frames/00000.png", "line": line(0.0)}]}


def _mutate(data, path, value):
    """Replace the value at a walk through ``path`` (keys or indices taken modulo sizes)."""
    node = data
    for step in path[:-1]:
        if isinstance(node, dict) and node:
            key = step if step in node else sorted(node)[len(step) % len(node)]
            if not isinstance(node[key], (dict, list)):
                break
            node = node[key]
        elif isinstance(node, list) and node:
            nxt = node[len(step) % len(node)]
            if not isinstance(nxt, (dict, list)):
                break
            node = nxt
    if isinstance(node, dict):
        node[path[-1]] = value
    elif isinstance(node, list) and node:
        node[len(path[-1]) % len(node)] = value
    return data


def _check_open(raw: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "frames").mkdir()
        cv2.imwrite(str(folder / "frames" / "00000.png"), np.zeros((H, W), np.uint8))
        (folder / "sequence.json").write_bytes(raw)
        try:
            seq = Sequence.open(folder)
        except FormatError as e:
            assert str(e) and "\n" not in str(e)
            return
        for _ in seq:
            pass


_fuzz = settings(max_examples=150, deadline=None,
                 suppress_health_check=[HealthCheck.too_slow])


@_fuzz
@given(st.one_of(_json, st.dictionaries(st.sampled_from(_KEYS), _json, max_size=6)))
def test_fuzz_arbitrary_json(value):
    _check_open(json.dumps(value).encode())


@_fuzz
@given(st.lists(st.sampled_from(_KEYS), min_size=1, max_size=5), _json)
def test_fuzz_mutated_valid_sequence(path, value):
    _check_open(json.dumps(_mutate(_valid(), path, value)).encode())


@_fuzz
@given(st.binary(max_size=200))
def test_fuzz_arbitrary_bytes(raw):
    _check_open(raw)
