"""``insitu mark --run`` end to end on the simulated rig: the part marked with a progress
record, the resume, the camera's read-back, a changed job refused for resuming."""

import json

import numpy as np
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.marking import read_job

runner = CliRunner()
SQUARE = ('<svg xmlns="http://www.w3.org/2000/svg" width="20mm" height="10mm" '
          'viewBox="0 0 20 10"><rect x="0" y="0" width="20" height="10" fill="black"/></svg>')


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_run_marks_the_part_records_progress_resumes_and_inspects(tmp_path):
    (tmp_path / "rect.svg").write_text(SQUARE)
    # a measured-looking top of the step block's 3 mm step (x ±10, y −40…−20)
    g = np.meshgrid(np.arange(-10, 10 + 1e-9, 0.2), np.arange(-40, -20 + 1e-9, 0.2))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    z = 3.0 + np.random.default_rng(0).normal(0, 0.005, len(xy))
    write_ply(tmp_path / "step3.ply", PointCloud(np.column_stack([xy, z])))
    out, img = tmp_path / "job.json", tmp_path / "inspect.png"
    args = ("mark", "--cloud", tmp_path / "step3.ply", "--pattern", tmp_path / "rect.svg",
            "--at", 0.0, -30.0, "--width", 6, "-o", out, "--run")
    res = _run(*args, "--preview", "--inspect", img)
    assert res.exit_code == 0, res.output
    progress = json.loads((tmp_path / "job.progress.json").read_text())
    assert progress["state"] == "done" and progress["completed"] == len(read_job(out).paths)
    assert img.stat().st_size > 10_000 and (tmp_path / "inspect.raw.png").stat().st_size > 10_000
    assert "read back by the camera" in res.output and "wrote " in res.output
    res = _run(*args, "--resume")
    assert res.exit_code == 0 and "nothing left to mark: " in res.output, res.output
    # a job that no longer matches the file cannot be resumed
    res = _run(*args[:-5], "--width", 5, "-o", out, "--run", "--resume")
    assert res.exit_code == 1 and "does not hold this job" in res.output
