"""How files written by earlier versions of insitu are read: for each kind of JSON file of
insitu's own, the step that brings a file of schema version n to n + 1. A reader
(:func:`insitu.formats.json_file.load_json_model`) applies the steps from the file's
``schema_version`` to the newest before it validates, so a model's defaults never stand in
for a value an older file left out — the step writes the value that file meant.

| kind | newest | what the steps add |
|---|---|---|
| ``height-calibration`` | 2 | v1 → v2: ``centres`` written whole; a v1 file left out the settings added after it was made, which it was extracted without: ``smooth_grains`` 0 (a fixed smoothing window), ``background`` false (the paper's gray-centroid threshold, Eq. 7), ``extend_ends`` false, ``end_fraction`` 0.5; a v1 file without ``centres`` was made with Steger's centres and those |
| ``camera``, ``scan-head``, ``rig``, ``field-correction``, ``part-pose`` | 1 | — |

The other files (recorded sequences, mark jobs and their journals, pens, projects, recipes,
production logs, serial counters, point clouds) carry their own ``format`` name and version
and are read by their own modules (docs/formats.md); fields added to them since their
version 1 are optional, with the value an older file meant as their default.
"""

from __future__ import annotations

from collections.abc import Callable

_CENTRES_V1 = {"method": "steger", "k": 0.3, "subtract": False, "smooth_half_window": 7,
               "jump_px": 1.0, "end_fraction": 0.5, "smooth_grains": 0.0,
               "background": False, "extend_ends": False}


def _height_1_to_2(data: dict) -> dict:
    centres = data.get("centres")
    if isinstance(centres, dict):
        centres = {**_CENTRES_V1, **centres}
    elif centres is None:
        centres = dict(_CENTRES_V1)
    return {**data, "centres": centres, "schema_version": 2}


STEPS: dict[str, dict[int, Callable[[dict], dict]]] = {
    "height-calibration": {1: _height_1_to_2},
}
"""kind → {version n: the step from n to n + 1}."""


def newest(kind: str | None) -> int:
    """The schema version this insitu writes for files of ``kind``."""
    return 1 + len(STEPS.get(kind or "", {}))


def migrate(kind: str | None, data: dict) -> dict:
    """``data`` (a file's JSON object of ``kind``) brought to the newest schema version; a
    file without ``schema_version`` is version 1; a version this insitu does not know is
    left to the model's validation to refuse."""
    steps = STEPS.get(kind or "", {})
    version = data.get("schema_version", 1)
    while isinstance(version, int) and not isinstance(version, bool) and version in steps:
        data = steps[version](data)
        version = data["schema_version"]
    return data
