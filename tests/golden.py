"""The golden command listing (tests/data/golden_small_job.txt): the commands the driver sends
for a small two-path job on the nominal head. The unit test compares with the file; only
``scripts/regen-golden.py`` writes it, after a change to the command stream was reviewed."""

from pathlib import Path

import numpy as np

from insitu.devices.galvo import RecordingController
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import GalvoDriver, LaserOverride, LaserParams, make_job, run_job

GOLDEN = Path(__file__).parent / "data" / "golden_small_job.txt"
HEAD = TwoMirrorHead(350.0, 12.0)


def small_job():
    return make_job([np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 5.0, 1.0]]),
                     np.array([[-5.0, -5.0, 2.0], [-5.0, 5.0, 2.0]])],
                    LaserParams(power_pct=30, frequency_khz=20, mark_speed_mm_s=500,
                                jump_speed_mm_s=3000), {1: LaserOverride(power_pct=50.0)})


def mark_small_job():
    """(run result, the RecordingController that received the commands)."""
    rc = RecordingController()
    return run_job(small_job(), GalvoDriver(HEAD), rc), rc
