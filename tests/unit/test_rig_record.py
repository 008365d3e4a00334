"""Clouds and jobs record the rig they came from; marking on another rig or workpiece is
refused naming both, nothing fired; files without the record are marked with a warning."""

import inspect
import json
import threading

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli import main as cli_main
from insitu.cli import scan as cli_scan
from insitu.errors import FormatError, SafetyError
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.formats.project import SIM_BINNING, RigChoice
from insitu.marking import make_job, read_job, write_job
from insitu.services.station import connect
from insitu.ui.model import operations

runner = CliRunner()
SQUARE = ('<svg xmlns="http://www.w3.org/2000/svg" width="20mm" height="10mm" '
          'viewBox="0 0 20 10"><rect x="0" y="0" width="20" height="10" fill="black"/></svg>')
ARC = {"workpiece": "arc", "seed": 0, "binning": 1}


def _run(*args):
    return runner.invoke(cli_main.app, [str(a) for a in args])


def _cloud(path, rig=None):
    """The top of the step block's 3 mm step (x ±10, y −40…−20), recording ``rig``."""
    g = np.meshgrid(np.arange(-10, 10.01, 0.2), np.arange(-40, -19.99, 0.2))
    pts = np.column_stack([g[0].ravel(), g[1].ravel(), np.full(g[0].size, 3.0)])
    write_ply(path, PointCloud(pts, {"quality": np.ones(len(pts))}, rig))
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("rigrec")
    (d / "rect.svg").write_text(SQUARE)
    _cloud(d / "arc.ply", ARC)
    _cloud(d / "step.ply", {"workpiece": "step-block", "seed": 0, "binning": 2})
    _cloud(d / "old.ply")
    return d


def _mark(files, cloud, out, *extra):
    return _run("mark", "--cloud", files / cloud, "--pattern", files / "rect.svg", "--at", 0.0,
                -30.0, "--width", 6, "-o", out, *extra)


def test_one_binning_default_for_commands_gui_and_projects():
    assert RigChoice().binning == SIM_BINNING == 1
    for command in (cli_main.gui, cli_scan.scan):
        assert inspect.signature(command).parameters["binning"].default == SIM_BINNING


def test_the_record_goes_through_the_ply_header(tmp_path, files):
    assert read_ply(files / "arc.ply").rig == ARC
    assert read_ply(files / "old.ply").rig is None
    assert np.allclose(read_ply(files / "arc.ply").points, read_ply(files / "old.ply").points)
    data = (files / "arc.ply").read_bytes()
    assert data.startswith(b"ply\nformat binary_little_endian 1.0\ncomment insitu-rig {")
    (tmp_path / "bad.ply").write_bytes(data.replace(b'"seed": 0', b'"seed": "x"'))
    with pytest.raises(FormatError, match=r"bad.ply: header line 3 \(insitu-rig\): expected"):
        read_ply(tmp_path / "bad.ply")


def test_station_records_and_checks_its_rig(tmp_path):
    with connect(workpiece="arc") as st:
        assert st.record == {"workpiece": "arc", "seed": 0, "binning": SIM_BINNING}
        assert st.check_source(tmp_path / "c.ply", {**ARC, "binning": 4}, "cloud") is None
        with pytest.raises(SafetyError, match="simulated rig, workpiece step-block.*"
                                              "the station is simulated rig, workpiece arc"):
            st.check_source(tmp_path / "c.ply", {"workpiece": "step-block", "seed": 0}, "cloud")
        with pytest.raises(SafetyError, match="seed 3"):
            st.check_source(tmp_path / "j.json", {**ARC, "seed": 3}, "job")
        assert "does not record the rig" in st.check_source(tmp_path / "j.json", None, "job")


def test_mark_run_on_another_workpiece_is_refused_nothing_fired(files, tmp_path):
    out = tmp_path / "job.json"
    res = _mark(files, "arc.ply", out, "--run")
    assert res.exit_code == 1 and isinstance(res.exception, SystemExit), res.output
    line = " ".join(res.output.split())
    assert "measured on simulated rig, workpiece arc, seed 0, binning 1, the station is " \
           "simulated rig, workpiece step-block" in line, res.output
    assert not out.exists() and not (tmp_path / "job.progress.json").exists()
    # a cloud of the station's workpiece (at another binning) marks; the job records its rig
    res = _mark(files, "step.ply", out, "--run")
    assert res.exit_code == 0, res.output
    assert read_job(out).rig == {"workpiece": "step-block", "seed": 0, "binning": 2}
    assert json.loads(out.read_text())["rig"]["workpiece"] == "step-block"
    assert json.loads((tmp_path / "job.progress.json").read_text())["state"] == "done"


def test_mark_run_on_a_cloud_without_record_warns(files, tmp_path):
    out = tmp_path / "job.json"
    res = _mark(files, "old.ply", out, "--run")
    assert res.exit_code == 0, res.output
    assert "warning: " in res.output and "does not record the rig it was measured on" in \
        " ".join(res.output.split())
    assert read_job(out).rig is None and "rig" not in json.loads(out.read_text())


def test_job_run_checks_the_jobs_rig(files, tmp_path):
    paths = [np.array([[-2.0, -30.0, 3.0], [2.0, -30.0, 3.0]])]
    job = tmp_path / "arc.json"
    write_job(job, make_job(paths).model_copy(update={"rig": ARC}))
    assert read_job(job).rig == ARC
    res = _run("job", "run", job)
    assert res.exit_code == 1 and "the job was planned for simulated rig, workpiece arc" in \
        " ".join(res.output.split()), res.output
    assert not (tmp_path / "arc.progress.json").exists()
    old = tmp_path / "old.json"
    write_job(old, make_job(paths))
    res = _run("job", "run", old)
    assert res.exit_code == 0 and "does not record the rig it was planned for" in \
        " ".join(res.output.split()), res.output
    bad = tmp_path / "bad.json"
    bad.write_text(job.read_text().replace('"workpiece": "arc"', '"part": "arc"'))
    res = _run("job", "run", bad)
    assert res.exit_code == 1 and "bad.json" in res.output, res.output


def test_the_application_refuses_a_job_of_another_workpiece(tmp_path):
    job = make_job([np.array([[-2.0, -30.0, 3.0], [2.0, -30.0, 3.0]])])
    with connect() as st, pytest.raises(SafetyError, match="workpiece arc.*workpiece step"):
        operations.mark(job.model_copy(update={"rig": ARC}), st, tmp_path / "j.json", None,
                        threading.Event())
    assert not (tmp_path / "j.json").exists()
