"""``insitu job run`` in its own process on the simulated rig, stopped from outside: SIGTERM and
SIGHUP leave the laser off and the record interrupted; SIGKILL at random moments, each run
resumed, marks every path once (tests/kill_campaign.py counts it against the simulated
controller's mark log)."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.marking import history, make_job, progress_path_for, read_job, read_progress, write_job
from kill_campaign import campaign


def _job(n, points):
    t = np.linspace(0.0, 1.0, points)
    return make_job([np.column_stack([x + 2 * t, np.sin(3 * t), 0 * t])
                     for x in np.linspace(-10, 10, n)])


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_sigterm_and_sighup_leave_the_laser_off_and_the_record_interrupted(tmp_path, sig):
    job_path, log = tmp_path / "job.json", tmp_path / "marks.log"
    write_job(job_path, _job(400, 12))
    p = subprocess.Popen([sys.executable, "-c", "from insitu.cli.main import main; main()",
                          "job", "run", str(job_path)],
                         env={**os.environ, "INSITU_SIM_MARK_LOG": str(log)},
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    journal = tmp_path / "job.journal.jsonl"
    t_end = time.monotonic() + 120
    while p.poll() is None and time.monotonic() < t_end and (
            not journal.exists() or journal.read_text().count('"done"') < 20):
        time.sleep(0.01)
    p.send_signal(sig)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 1, out + err
    assert f"marking stopped by {sig.name}; the laser is off" in err
    s = history(read_job(job_path), progress_path_for(job_path))
    assert s.state == "interrupted" and 20 <= len(s.done) < 400
    assert read_progress(progress_path_for(job_path))["state"] == "interrupted"
    tail = [w for w in log.read_text().splitlines() if w]
    assert tail[-1] == "O"                              # the sim controller's laser-off
    res = CliRunner().invoke(app, ["job", "run", str(job_path)])
    assert res.exit_code == 1 and "resume it, or restart it" in res.output
    shown = CliRunner().invoke(app, ["job", "show", str(job_path)]).output
    assert "interrupted" in shown and f"{len(s.done)} of 400 paths done" in shown


def test_kill_and_resume_marks_every_path_once(tmp_path):
    """Five SIGKILLs in jobs of 200 paths: no path twice in full, none skipped, every kill
    mid-path reported as a cut path."""
    c = campaign(kills=5, n_paths=200, seed=3, folder=tmp_path)
    assert not c.problems, c.problems
    assert c.stats["kills"] == 5 and c.stats["marked twice in full"] == 0
    assert c.stats["skipped"] == 0
    assert c.stats["cut paths reported"] >= c.stats["cut mid-path"]
