"""``insitu mark`` end to end: placement as asked, refusals that write nothing, ``job show``
and ``job run``; marking on the simulated rig with --run is tests/integration/test_mark_run.py."""

import re

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.marking import read_job

runner = CliRunner()
SQUARE = ('<svg xmlns="http://www.w3.org/2000/svg" width="20mm" height="10mm" '
          'viewBox="0 0 20 10"><rect x="0" y="0" width="20" height="10" fill="black"/></svg>')


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def _cloud(path, x0, x1, y0, y1, z, step=0.2, hole=None):
    """A measured-looking flat patch at height z (mm), with a round hole (cx, cy, r) if given."""
    g = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    if hole is not None:
        xy = xy[np.hypot(xy[:, 0] - hole[0], xy[:, 1] - hole[1]) > hole[2]]
    z = z + np.random.default_rng(0).normal(0, 0.005, len(xy))
    write_ply(path, PointCloud(np.column_stack([xy, z])))
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("mark")
    (d / "rect.svg").write_text(SQUARE)
    # the top of the step block's 3 mm step (x ±10, y −40…−20 on the simulated rig)
    _cloud(d / "step3.ply", -10, 10, -40, -20, 3.0)
    return d


def _flat(output: str) -> str:
    """A table's text on one line: rich's frame and wrapping gone."""
    return " ".join(re.sub(r"[│┃┌┐└┘├┤┬┴┼─]", " ", output).split())


def _points(job_path):
    return np.vstack([p.points for p in read_job(job_path).paths])


def test_job_is_placed_scaled_and_turned_as_asked(files, tmp_path):
    out = tmp_path / "job.json"
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern", files / "rect.svg",
               "--at", 1.0, -30.0, "--width", 8, "--hatch", 0.25, "-o", out)
    assert res.exit_code == 0, res.output
    p = _points(out)
    lo, hi = p[:, :2].min(0), p[:, :2].max(0)
    assert np.allclose(0.5 * (lo + hi), [1.0, -30.0], atol=0.02)
    assert np.allclose(hi - lo, [8.0, 4.0], atol=0.02)
    assert np.all(np.abs(p[:, 2] - 3.0) < 0.02)
    assert "hatch 0.25 mm" in res.output and "estimated time" in res.output
    assert len(read_job(out).paths) > 10                  # outline + ~16 hatch lines

    turned = tmp_path / "turned.json"
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern", files / "rect.svg",
               "--at", 1.0, -30.0, "--width", 8, "--rotate", 90, "-o", turned)
    assert res.exit_code == 0, res.output
    q = _points(turned)
    assert np.allclose(q[:, :2].max(0) - q[:, :2].min(0), [4.0, 8.0], atol=0.02)


@pytest.mark.parametrize("args, message", [
    (("--at", 1.0, -30.0, "--width", 30), "over a hole in the point cloud"),
    (("--at", 1.0, -30.0, "--width", 8, "--mode", "cone"), "--mode 'cone'"),
    (("--at", 1.0, -30.0, "--width", -2), "--width: -2 is outside 0.001 … 2000 mm"),
    (("--at", 1.0, -30.0, "--width", 8, "--preview"), "go with --run"),
    (("--at", 1.0, -30.0, "--width", 8, "--power", 120), "--power: 120 is outside 0 … 100 %"),
])
def test_refusals_name_the_problem_and_keep_the_old_job(files, tmp_path, args, message):
    out = tmp_path / "job.json"
    out.write_text("the previous job")
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern", files / "rect.svg", *args,
               "-o", out)
    assert res.exit_code == 1
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and message in lines[0], res.output
    assert out.read_text() == "the previous job"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["job.json"]


def test_pattern_outside_the_field_and_over_a_hole(tmp_path):
    (tmp_path / "rect.svg").write_text(SQUARE)
    edge = _cloud(tmp_path / "edge.ply", 90, 110, -10, 10, 0.0)
    res = _run("mark", "--cloud", edge, "--pattern", tmp_path / "rect.svg", "--at", 98, 0,
               "--width", 8, "-o", tmp_path / "a.json")
    assert res.exit_code == 1 and "outside the scan field ±100 × ±100 mm" in res.output
    holed = _cloud(tmp_path / "holed.ply", -10, 10, -10, 10, 0.0, hole=(2.0, 1.0, 1.5))
    res = _run("mark", "--cloud", holed, "--pattern", tmp_path / "rect.svg", "--at", 0, 0,
               "--width", 8, "--hatch", 0.2, "-o", tmp_path / "b.json")
    assert res.exit_code == 1 and "over a hole" in res.output
    where = re.search(r"\(x, y\) = \(([-\d.]+), ([-\d.]+)\) mm", res.output)
    assert np.hypot(float(where[1]) - 2.0, float(where[2]) - 1.0) < 1.6   # it names the place
    assert not (tmp_path / "a.json").exists() and not (tmp_path / "b.json").exists()


def test_bad_inputs(files, tmp_path):
    out = tmp_path / "job.json"
    for cloud, pattern, message in (
            (tmp_path / "none.ply", files / "rect.svg", "no such point cloud file"),
            (files / "step3.ply", tmp_path / "none.svg", "no such pattern file"),
            (files / "step3.ply", "text:", "empty")):
        res = _run("mark", "--cloud", cloud, "--pattern", pattern, "--at", 0, -30, "--width", 5,
                   "-o", out)
        assert res.exit_code == 1 and message in res.output, res.output
        assert isinstance(res.exception, SystemExit) and not out.exists(), res.exception


def test_job_show_and_run(files, tmp_path):
    out = tmp_path / "job.json"
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern", files / "rect.svg", "--at",
               0.0, -30.0, "--width", 6, "--hatch", 0.5, "-o", out)
    assert res.exit_code == 0, res.output
    n = len(read_job(out).paths)
    res = _run("job", "show", out)
    assert res.exit_code == 0 and f"{n} (" in res.output and "estimated time" in res.output
    assert "last run" not in res.output
    res = _run("job", "run", out)
    assert res.exit_code == 0 and f"marked paths 1…{n} of {n} (done)" in res.output, res.output
    assert f"done: {n} of {n} paths" in _run("job", "show", out).output
    (tmp_path / "bad.json").write_text('{"format": "insitu-job/1", "paths": []}')
    res = _run("job", "run", tmp_path / "bad.json")
    assert res.exit_code == 1 and "bad.json" in res.output and isinstance(res.exception, SystemExit)
    assert not (tmp_path / "bad.progress.json").exists()


def test_codes_say_whether_they_decode_and_a_bad_one_is_refused(files, tmp_path):
    out = tmp_path / "dm.json"
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern",
               'datamatrix:"(01)09501101530003(21)0042";module=0.3', "--at", 0, -30, "-o", out)
    assert res.exit_code == 0, res.output
    text = _flat(res.output)
    assert "decodes yes: datamatrix:(01)09501101530003(21)0042 (module 0.3 mm)" in text
    assert "along the modules" in text and out.exists()
    bad = tmp_path / "bad.json"
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern", "qr:HELLO;module=0.25",
               "--at", 0, -30, "--hatch", 0.6, "-o", bad)
    assert res.exit_code != 0 and not bad.exists()
    assert len(res.output.strip().splitlines()) == 1
    assert "qr:HELLO: does not decode" in res.output and "nothing written" in res.output
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern", "qr:HELLO;module=0.25",
               "--at", 0, -30, "--hatch", 0.6, "--force", "-o", bad)
    assert res.exit_code == 0 and bad.exists() and "decodes NO: qr:HELLO" in _flat(res.output)


def test_fill_option_fills_a_dxf_frame_only_when_asked(tmp_path, files):
    import ezdxf
    doc = ezdxf.new()
    doc.modelspace().add_lwpolyline([(0, 0), (8, 0), (8, 4), (0, 4)], close=True)
    doc.saveas(tmp_path / "frame.dxf")
    jobs = {}
    for fill in ("auto", "all"):
        jobs[fill] = tmp_path / f"{fill}.json"
        res = _run("mark", "--cloud", files / "step3.ply", "--pattern", tmp_path / "frame.dxf",
                   "--at", 0, -30, "--width", 8, "--hatch", 0.5, "--fill", fill, "-o",
                   jobs[fill])
        assert res.exit_code == 0, res.output
        assert "loaded units: $INSUNITS 6 (Meters)" in _flat(res.output)
    assert len(read_job(jobs["auto"]).paths) == 1          # the frame, a line
    assert len(read_job(jobs["all"]).paths) > 8            # outline + 8 hatch lines
    res = _run("mark", "--cloud", files / "step3.ply", "--pattern", tmp_path / "frame.dxf",
               "--at", 0, -30, "--width", 8, "--fill", "some", "-o", tmp_path / "x.json")
    assert res.exit_code != 0 and "--fill 'some': expected one of auto, all, none" in res.output


def _gapped_step(path):
    """A 3 → 5 mm step at y = −20 whose wall the cloud does not show: lines along y every
    0.5 mm, the lower level lost 0.3 mm behind the top edge."""
    xs, ys = np.meshgrid(np.arange(-10.0, 10.01, 0.5), np.arange(-30.0, -10.0, 0.15) + 0.01)
    x, y = xs.ravel(), ys.ravel()
    keep = (y < -20.3) | (y > -20.0)
    z = np.where(y > -20.0, 5.0, 3.0)
    write_ply(path, PointCloud(np.column_stack([x, y, z])[keep]))


def test_the_summary_says_what_a_step_left_unmarked(files, tmp_path):
    """The job marks neither the wall nor the strip beside it that the cloud does not show,
    and says so."""
    _gapped_step(tmp_path / "step.ply")
    out = tmp_path / "job.json"
    res = _run("mark", "--cloud", tmp_path / "step.ply", "--pattern", files / "rect.svg",
               "--at", 0, -20, "--width", 8, "--hatch", 0.1, "-o", out)
    assert res.exit_code == 0, res.output
    p = _points(out)
    assert np.abs(p[:, 2] - np.where(p[:, 1] > -20.0, 5.0, 3.0)).max() < 0.10
    assert not ((p[:, 1] > -20.3) & (p[:, 1] < -20.0)).any()
    m = re.search(r"unmarked at walls (\d+\.\d\d) mm of (\d+) mm of path \((\d+\.\d)%\)",
                  _flat(res.output))
    assert m, res.output
    assert float(m[1]) > 2 * 8.0 and 1.0 < float(m[3]) < 20.0     # hatch rows in the strip


def test_a_code_the_unmarked_strip_breaks_is_refused(tmp_path):
    """A QR code whose middle module row the unmarked strip runs through does not decode: it
    is refused, naming the wall, after the warning of what the step leaves unmarked (the
    lines the application's Place dock shows too); nothing is written."""
    _gapped_step(tmp_path / "step.ply")
    out = tmp_path / "qr.json"
    res = _run("mark", "--cloud", tmp_path / "step.ply", "--pattern", "qr:HELLO;module=0.5",
               "--at", 0, -20, "-o", out)
    assert res.exit_code == 1 and not out.exists()
    lines = res.output.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith("warning: unmarked at walls"), lines
    assert "does not decode" in lines[1] and "left unmarked at a step's wall" in lines[1]
