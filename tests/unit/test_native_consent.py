"""No native code without the station's consent: a library a rig file (or the project that
names it) asks for is loaded only when the station file allows it. A canary library whose
constructor creates a file proves whether it was loaded."""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fakes.canary import build, project_naming
from fakes.station import allow
from insitu.devices.native import allowed_library, read_station, station_path
from insitu.devices.rtc import RtcLibrary
from insitu.errors import ConfigError, DeviceError
from insitu.marking import make_job
from insitu.services.project import open_project
from insitu.services.serials import save_job

SRC = Path(__file__).parents[2] / "src"


@pytest.fixture
def canary(tmp_path):
    return build(tmp_path)


def run_cli(*args) -> subprocess.CompletedProcess:
    """``insitu ARGS`` in a fresh process (its own dynamic loader, the test run's station)."""
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    return subprocess.run([sys.executable, "-c", "from insitu.cli.main import main; main()",
                           *map(str, args)], capture_output=True, text=True, env=env,
                          timeout=120)


def test_the_canary_proves_loading(canary):
    lib, marker = canary
    allow(lib)
    with pytest.raises(DeviceError, match="has no function .*not an RTC6 library"):
        RtcLibrary(lib, 6)
    assert marker.read_text() == "loaded\n"          # loaded: its constructor ran


def test_a_library_not_on_the_allow_list_is_never_loaded(canary):
    lib, marker = canary
    with pytest.raises(ConfigError) as e:
        RtcLibrary(lib, 6)
    msg = str(e.value)
    assert "\n" not in msg and str(lib) in msg and str(station_path()) in msg
    assert "options.rtc.library" in msg and "native_libraries" in msg
    assert not marker.exists()


def test_a_genicam_producer_not_on_the_allow_list_is_never_loaded(tmp_path):
    pytest.importorskip("harvesters")
    from insitu.devices.camera_genicam import GenICamCamera

    lib, marker = build(tmp_path, "producer.cti")
    with pytest.raises(ConfigError, match="options.camera.producer: native library .*producer.cti"
                                          " is not allowed by the station file"):
        GenICamCamera(lib)
    assert not marker.exists()


def test_no_station_file_allows_nothing(canary, tmp_path, monkeypatch):
    lib, marker = canary
    monkeypatch.setenv("INSITU_STATION", str(tmp_path / "absent.json"))
    assert read_station() is None
    with pytest.raises(ConfigError, match=r"absent.json \(none there\).*\"schema_version\": 1"):
        allowed_library(lib, "options.rtc.library")
    assert not marker.exists()


def test_symlinks_are_resolved_before_comparing(canary, tmp_path):
    lib, marker = canary
    link = tmp_path / "project" / "librtc6.so"
    link.parent.mkdir()
    link.symlink_to(lib)
    with pytest.raises(ConfigError, match=f"{link} \\(= {lib}\\) is not allowed"):
        allowed_library(link, "options.rtc.library")
    allowed_dir = tmp_path / "opt"
    allowed_dir.mkdir()
    (allowed_dir / "librtc6.so").symlink_to(lib)
    allow(allowed_dir / "librtc6.so")             # the station names the file by a link
    assert allowed_library(link, "options.rtc.library") == lib
    assert not marker.exists()


def test_a_pinned_sha256_must_match(canary, tmp_path):
    lib, marker = canary
    allow(lib, sha256="0" * 64)
    with pytest.raises(ConfigError, match="differs from the sha256"):
        RtcLibrary(lib, 6)
    assert not marker.exists()
    allow(lib, sha256=hashlib.sha256(lib.read_bytes()).hexdigest())
    assert allowed_library(lib, "options.rtc.library") == lib


@pytest.mark.parametrize("entry, field", [({"path": "lib/librtc6.so"}, "path"),
                                          ({"path": "/opt/x.so", "sha256": "abc"}, "sha256"),
                                          ({"path": "/opt/x.so", "hash": "abc"}, "hash")])
def test_a_bad_station_file_is_one_line(tmp_path, monkeypatch, entry, field):
    station = tmp_path / "station.json"
    station.write_text(json.dumps({"kind": "station", "schema_version": 1,
                                   "native_libraries": [entry]}))
    monkeypatch.setenv("INSITU_STATION", str(station))
    with pytest.raises(ConfigError, match=f"^{station}: native_libraries\\[0\\].{field}: "):
        read_station()


def test_opening_a_project_loads_nothing_and_job_run_says_why(canary, tmp_path):
    lib, marker = canary
    project, rig = project_naming(tmp_path, lib)
    opened = open_project(project)
    assert opened.project.rig.rig_file == rig
    assert not marker.exists()
    job = tmp_path / "job.json"
    save_job(job, make_job([np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])]).model_copy(
        update={"rig": {"rig_file": rig.name}}))          # planned for this rig: no warning
    res = run_cli("job", "run", job, "--rig", rig)
    assert res.returncode == 1, res.stdout + res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr
    assert "native library" in lines[0] and lib.name in lines[0] and "not allowed" in lines[0]
    assert "station" in lines[0]
    assert not marker.exists()
    allow(lib)                          # with the station's consent it is loaded
    res = run_cli("job", "run", job, "--rig", rig)
    assert res.returncode == 1 and "not an RTC6 library" in res.stderr
    assert marker.exists()
