"""The station file of a test run: :func:`isolated_station` points ``INSITU_STATION`` at an
empty one for the whole session (the unit and GUI tiers use it, so a developer's own
~/.config/insitu/station.json never counts; the hardware tier uses the station's own), and
:func:`allow` adds a native library (a fake compiled at test time, a GenTL producer) to its
allow-list, as a station's administrator would."""

from __future__ import annotations

import json
import os
from pathlib import Path

EMPTY = {"kind": "station", "schema_version": 1, "native_libraries": []}


def isolated_station(tmp_path_factory):
    """Generator of a session fixture: ``INSITU_STATION`` → an empty station file of this
    run (restored afterwards)."""
    old = os.environ.get("INSITU_STATION")
    path = tmp_path_factory.mktemp("station") / "station.json"
    path.write_text(json.dumps(EMPTY))
    os.environ["INSITU_STATION"] = str(path)
    yield path
    if old is None:
        os.environ.pop("INSITU_STATION", None)
    else:
        os.environ["INSITU_STATION"] = old


def allow(library: Path, sha256: str | None = None) -> Path:
    """Allow ``library`` to be loaded from now on in this test run; returns it."""
    path = Path(os.environ["INSITU_STATION"])
    data = json.loads(path.read_text())
    entry = {"path": str(Path(library).absolute())}
    if sha256 is not None:
        entry["sha256"] = sha256
    data["native_libraries"].append(entry)
    path.write_text(json.dumps(data))
    return library
