"""Variable data in mark jobs, end to end: ``insitu mark`` takes the counter's next serial when
it writes the job, a refused job takes none, a faulted or aborted job keeps its own (a resume
marks it, planning again takes the next), ``job show`` prints it, and a ``qr:"{serial}"`` job's
paths decode to the rendered serial."""

import json
import re
import threading

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.devices.galvo import RecordingController
from insitu.errors import DeviceError
from insitu.formats.counter import locked, read_counter
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import GalvoDriver, Placement, progress_path_for, read_job, read_progress
from insitu.marking.verify import check_code
from insitu.services.mark import mark
from insitu.services.serials import job_variables

runner = CliRunner()
QR = 'qr:"{serial}";ec=H'


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def _flat(output: str) -> str:
    return " ".join(re.sub(r"[│┃┌┐└┘├┤┬┴┼─]", " ", output).split())


@pytest.fixture(scope="module")
def cloud(tmp_path_factory):
    """The top of the step block's 3 mm step (x ±10, y −40…−20 on the simulated rig)."""
    path = tmp_path_factory.mktemp("serial") / "step3.ply"
    g = np.meshgrid(np.arange(-10, 10.01, 0.2), np.arange(-40, -19.99, 0.2))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    write_ply(path, PointCloud(np.column_stack([xy, np.full(len(xy), 3.0)])))
    return path


def _mark(cloud, out, pattern=QR, *more):
    return _run("mark", "--cloud", cloud, "--pattern", pattern, "--at", 0, -30, "--width", 8,
                "-o", out, *more)


def test_each_job_takes_the_next_serial_and_job_show_prints_it(cloud, tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    res = _mark(cloud, a, QR, "--serial-start", 41)
    assert res.exit_code == 0, res.output
    assert "serial 41 (issued from serial.counter.json)" in _flat(res.output)
    rec = job_variables(read_job(a))
    assert rec.serial == 41 and [(t.spec, t.text) for t in rec.texts] == [(QR, "41")]
    res = _mark(cloud, b, 'text:"SN {serial:05d} {date:%Y}";size=2')
    assert res.exit_code == 0, res.output
    rec = job_variables(read_job(b))
    assert rec.serial == 42 and rec.texts[0].text == f"SN 00042 {rec.time[:4]}"
    counter = read_counter(tmp_path / "serial.counter.json")
    assert counter.next == 43 and [(i.serial, i.job) for i in counter.issued] == [
        (41, "a.json"), (42, "b.json")]
    assert counter.issued[0].digest == read_job(a).digest()
    res = _run("job", "show", a)
    text = _flat(res.output)
    assert res.exit_code == 0 and "serial 41; counter" in text and "next 43" in text, text
    assert 'text 41 ← qr:"{serial}";ec=H' in text
    res = _run("serial", "show", tmp_path / "serial.counter.json")
    assert res.exit_code == 0 and "next 43" in _flat(res.output) and "b.json" in res.output
    # a job without variable data shows none
    plain = tmp_path / "plain.json"
    assert _mark(cloud, plain, "qr:PLAIN").exit_code == 0
    assert "serial" not in _run("job", "show", plain).output


def test_the_marks_decode_to_the_rendered_serial(cloud, tmp_path):
    out, counter = tmp_path / "job.json", tmp_path / "parts.counter.json"
    res = _mark(cloud, out, QR, "--counter", counter, "--serial-start", 90417)
    assert res.exit_code == 0 and "decodes yes: qr:90417" in _flat(res.output), res.output
    job = read_job(out)
    assert job_variables(job, out).counter == "parts.counter.json"
    # decoded from the job file's own paths, in the frame of the rendered code
    placed = Placement('qr:"90417";ec=H', (0.0, -30.0), 8.0).placed()
    check, _ = check_code(placed, [p.points[:, :2] for p in job.paths], 0.05)
    assert check.ok and check.decoded == "90417"


def test_refusals_take_no_serial_and_write_nothing(cloud, tmp_path):
    out, counter = tmp_path / "job.json", tmp_path / "serial.counter.json"
    res = _mark(cloud, out)
    assert res.exit_code == 1 and "no such serial counter (a first serial creates one)" \
        in res.output and len(res.output.strip().splitlines()) == 1
    assert not out.exists() and not counter.exists()
    assert _mark(cloud, out, QR, "--serial-start", 1).exit_code == 0
    out.unlink()
    for pattern, more, message in (
            (QR, ("--serial-start", 5), "a serial counter exists (next 2)"),
            ('datamatrix:"(01){gtin}(21){serial}"', (), "field {gtin} has no value (give "
                                                        "it a value: gtin=VALUE)"),
            ('datamatrix:"(01){gtin}(21){serial}"', ("--var", "gtin=09506000134353"),
             "wrong check digit 3 (expected 2)"),
            ('qr:"{serial:.2f}"', (), "format spec '.2f' does not fit"),
            ("qr:PLAIN", ("--serial-start", 5), "--serial-start: no pattern uses {serial}")):
        res = _mark(cloud, out, pattern, *more)
        assert res.exit_code == 1 and message in _flat(res.output), res.output
        assert not out.exists()
    # --var gives the text's fields; --field still names the field correction
    res = _mark(cloud, out, 'qr:"{lot}{serial}"', "--var", "lot=A", "--field", tmp_path / "no.json")
    assert res.exit_code == 1 and "no.json: file not found" in res.output and not out.exists()
    # outside the focus range: refused by the checks, after the serial was read, before issued
    res = _run("mark", "--cloud", cloud, "--pattern", QR, "--at", 0, -30, "--width", 60,
               "-o", out)
    assert res.exit_code == 1 and not out.exists()
    assert read_counter(counter).next == 2


class FaultAt(RecordingController):
    """A board that stops answering after ``n`` commands."""

    def __init__(self, n: int):
        super().__init__()
        self.n = n

    def execute(self, commands):
        for c in commands:
            if len(self.commands) == self.n:
                raise DeviceError("scan head: no answer")
            super().execute([c])


@pytest.mark.parametrize("how", ["fault", "abort"])
def test_an_interrupted_job_keeps_its_serial_and_resumes_it(cloud, tmp_path, how):
    out = tmp_path / "part.json"
    assert _mark(cloud, out, QR, "--serial-start", 7).exit_code == 0
    job = read_job(out)
    driver, ppath = GalvoDriver(TwoMirrorHead(350.0, 12.0)), progress_path_for(out)
    if how == "fault":
        with pytest.raises(DeviceError):
            mark(job, driver, FaultAt(400), ppath)
    else:
        cancel = threading.Event()
        result = mark(job, driver, RecordingController(), ppath, cancel=cancel,
                      progress=lambda done, total: done == 30 and cancel.set())
        assert result.state == "cancelled"
    done = read_progress(ppath)["completed"]
    assert 0 < done < len(job.paths)
    counter = tmp_path / "serial.counter.json"
    assert read_counter(counter).next == 8                  # 7 stays issued
    # insitu mark --run --resume plans it again with the job's own serial and goes on (the
    # path the fault cut is marked again)
    cut = ["--cut-path", "remark"] if how == "fault" else []
    res = _mark(cloud, out, QR, "--run", "--resume", *cut)
    assert res.exit_code == 0, res.output
    assert f"marked paths {done + 1}…{len(job.paths)} of {len(job.paths)} (done" \
        in _flat(res.output) and "serial 7 (issued from serial.counter.json)" in _flat(res.output)
    assert read_job(out).digest() == job.digest() and job_variables(read_job(out)).serial == 7
    assert read_counter(counter).next == 8
    # planning the part again takes the next serial; 7 is never handed out again
    assert _mark(cloud, out).exit_code == 0
    assert job_variables(read_job(out)).serial == 8 and read_counter(counter).next == 9
    assert [i.serial for i in read_counter(counter).issued] == [7, 8]


def test_job_run_resume_marks_the_recorded_serial(cloud, tmp_path):
    out = tmp_path / "part.json"
    assert _mark(cloud, out, QR, "--serial-start", 3).exit_code == 0
    job = read_job(out)
    with pytest.raises(DeviceError):
        mark(job, GalvoDriver(TwoMirrorHead(350.0, 12.0)), FaultAt(200), progress_path_for(out))
    res = _run("job", "run", out, "--resume", "--cut-path", "remark")
    assert res.exit_code == 0 and "(done, cut path" in res.output, res.output
    assert "serial 3;" in _flat(_run("job", "show", out).output)
    assert json.loads(out.read_text())["variable_data"]["serial"] == 3
    assert read_counter(tmp_path / "serial.counter.json").next == 4


def test_serial_set_refuses_going_back_without_force(tmp_path):
    path = tmp_path / "c.json"
    assert _run("serial", "set", path, 10).exit_code == 0
    assert read_counter(path).next == 10
    with locked(path) as c:
        c.issue(10)
    res = _run("serial", "set", path, 10)
    assert res.exit_code == 1 and "serial 10 was issued already" in res.output
    assert read_counter(path).next == 11
    res = _run("serial", "set", path, 10, "--force")
    assert res.exit_code == 0 and read_counter(path).next == 10
    res = _run("serial", "show", tmp_path / "missing.json")
    assert res.exit_code == 1 and "no such serial counter" in res.output


def test_a_text_with_the_date_only_takes_no_serial(cloud, tmp_path):
    out = tmp_path / "dated.json"
    res = _mark(cloud, out, 'text:"{date:%Y} {lot}";size=2', "--var", "lot=L7")
    assert res.exit_code == 0, res.output
    rec = job_variables(read_job(out))
    assert rec.serial is None and rec.counter is None and rec.fields == {"lot": "L7"}
    assert rec.texts[0].text == f"{rec.time[:4]} L7"
    assert not (tmp_path / "serial.counter.json").exists()
    text = _flat(_run("job", "show", out).output)
    assert "serial" not in text and f"text {rec.time[:4]} L7" in text and "lot=L7" in text


@pytest.mark.parametrize("record, message", [
    ({"serial": "x", "time": "2026-01-01T00:00:00"}, "variable_data.serial: expected an integer"),
    ({"serial": 1}, "variable_data.time: missing (required)"),
    ({"serial": 1, "time": "yesterday"}, "variable_data.time: expected an ISO 8601 time"),
])
def test_a_bad_variable_data_record_is_one_line(tmp_path, record, message):
    path = tmp_path / "job.json"
    path.write_text(json.dumps({"paths": [{"points": [[0, 0, 0], [1, 0, 0]]}],
                                "variable_data": record}))
    res = _run("job", "show", path)
    assert res.exit_code == 1 and f"{path}: {message}" in _flat(res.output), res.output


def test_the_screen_plans_with_the_next_serial_and_refuses_a_bad_template(cloud, tmp_path):
    from insitu.formats.pointcloud import read_ply
    from insitu.services.mark_job import preview_plans
    from insitu.services.station import connect

    with locked(tmp_path / "serial.counter.json") as c:
        c.create(12)
    items = (Placement('qr:"{serial"', (0.0, -36.0), 4.0),
             Placement('qr:"{serial}";ec=H', (0.0, -28.0), 6.0),
             Placement("qr:PLAIN", (7.0, -36.0), 4.0))
    with connect(None) as station:
        out = preview_plans(station, read_ply(cloud), items, job_path=tmp_path / "p.job.json")
    assert out[0].plan is None and "expected '}' before end of string" in out[0].error
    assert out[1].plan.pattern.code.text == "12" and out[2].plan.pattern.code.text == "PLAIN"
    assert read_counter(tmp_path / "serial.counter.json").next == 12    # a preview takes none
