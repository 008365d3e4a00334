"""The mark job file (docs/formats.md, mark job): round trip, validation errors, time estimate."""

import json

import numpy as np
import pytest
from pydantic import ValidationError

from insitu.errors import FormatError
from insitu.marking import (
    LaserOverride,
    LaserParams,
    MarkJob,
    Timing,
    estimate_time,
    make_job,
    read_job,
    write_job,
)
from insitu.marking.job import corner_delays_us


def small_job(**kw):
    paths = [np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 5.0, 1.0]]),
             np.array([[-5.0, -5.0, 2.0], [-5.0, 5.0, 2.0]])]
    return make_job(paths, LaserParams(power_pct=30, frequency_khz=20, mark_speed_mm_s=500,
                                       jump_speed_mm_s=3000),
                    {1: LaserOverride(power_pct=50.0, mark_speed_mm_s=250.0)}, **kw)


def test_round_trip(tmp_path):
    job = small_job(timing=Timing(jump_delay_us=123.0))
    f = tmp_path / "job.json"
    write_job(f, job)
    assert [p.name for p in tmp_path.iterdir()] == ["job.json"]          # no temp left
    data = json.loads(f.read_text())
    assert data["format"] == "insitu-job/1" and data["frame"] == "scan-head"
    assert data["units"] == "mm" and data["laser"]["power_pct"] == 30.0
    assert data["paths"][1]["laser"] == {"power_pct": 50.0, "mark_speed_mm_s": 250.0}
    assert "laser" not in data["paths"][0]
    back = read_job(f)
    assert back.digest() == job.digest()
    for a, b in zip(job.paths, back.paths):
        np.testing.assert_array_equal(a.points, b.points)
    assert back.path_laser(0).power_pct == 30.0
    assert back.path_laser(1).power_pct == 50.0 and back.path_laser(1).mark_speed_mm_s == 250.0
    assert back.path_laser(1).frequency_khz == 20.0
    assert back.timing.jump_delay_us == 123.0


def test_minimal_file_and_unknown_fields(tmp_path):
    f = tmp_path / "j.json"
    f.write_text(json.dumps({"paths": [{"points": [[1, 2, 3], [4, 5, 6]], "note": "kept"}],
                             "made_by": "another tool"}))
    job = read_job(f)
    assert job.laser == LaserParams() and job.timing is None
    assert job.paths[0].points.dtype == np.float64
    write_job(f, job)
    again = json.loads(f.read_text())
    assert again["made_by"] == "another tool" and again["paths"][0]["note"] == "kept"


def test_write_to_missing_folder(tmp_path):
    with pytest.raises(FormatError, match="does not exist"):
        write_job(tmp_path / "nope" / "job.json", small_job())


def test_write_keeps_old_file_on_failure(tmp_path):
    f = tmp_path / "job.json"
    write_job(f, small_job())
    before = f.read_text()
    nan = LaserParams.model_construct(power_pct=float("nan"))
    bad = small_job().model_copy(update={"laser": nan})
    with pytest.raises((ValueError, FormatError)):
        write_job(f, bad)
    assert f.read_text() == before
    assert [p.name for p in tmp_path.iterdir()] == ["job.json"]


GOOD = {"format": "insitu-job/1", "laser": {"power_pct": 30.0}, "paths": [
    {"points": [[0, 0, 0], [1, 0, 0]]}, {"points": [[0, 1, 0], [1, 1, 0], [2, 1, 0]]}]}


def edit(path, value):
    data = json.loads(json.dumps(GOOD))
    node = data
    for k in path[:-1]:
        node = node[k]
    if value is KeyError:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return data


@pytest.mark.parametrize("data, expected", [
    (edit(["paths"], KeyError), "paths: missing (required)"),
    (edit(["paths", 1, "points", 2], [1, 2]),
     "paths[1].points[2]: expected 3 numbers [x, y, z], got [1, 2]"),
    (edit(["paths", 0, "points", 1], [1, "a", 2]), "paths[0].points[1]: expected 3 numbers"),
    (edit(["paths", 0, "points"], []), "paths[0].points: expected at least 1 point"),
    (edit(["paths", 0, "points"], "abc"), "paths[0].points: expected a list of [x, y, z] points"),
    (edit(["paths", 1, "points"], KeyError), "paths[1].points: missing (required)"),
    (edit(["paths"], {"a": 1}), "paths: expected a list"),
    (edit(["laser", "power_pct"], 150), "laser.power_pct: 150 is outside 0 … 100 %"),
    (edit(["laser", "mark_speed_mm_s"], 0), "laser.mark_speed_mm_s: 0 is outside 0.1 … 20000 mm/s"),
    (edit(["paths", 1, "laser"], {"power_pct": -1}),
     "paths[1].laser.power_pct: -1 is outside 0 … 100 %"),
    (edit(["format"], "insitu-job/2"), "format: expected 'insitu-job/1', got 'insitu-job/2'"),
    (edit(["units"], "inch"), "units: expected 'mm'"),
    (edit(["frame"], "camera"), "frame: expected 'scan-head'"),
])
def test_validation_errors_name_the_field(tmp_path, data, expected):
    f = tmp_path / "job.json"
    f.write_text(json.dumps(data))
    with pytest.raises(FormatError) as e:
        read_job(f)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(str(f))
    assert expected in msg


def test_non_finite_and_not_json(tmp_path):
    f = tmp_path / "job.json"
    f.write_text('{"paths": [{"points": [[0, 0, NaN], [1, 2, 3]]}]}')
    with pytest.raises(FormatError, match=r"paths\[0\]\.points\[0\]: expected 3 finite numbers"):
        read_job(f)
    f.write_text('{"paths": [')
    with pytest.raises(FormatError, match="not valid JSON"):
        read_job(f)
    f.write_text("[1, 2]")
    with pytest.raises(FormatError, match="expected a JSON object"):
        read_job(f)
    with pytest.raises(FormatError, match="no such job file"):
        read_job(tmp_path / "missing.json")


def test_corner_delays():
    t = Timing(polygon_delay_us=100.0, min_corner_deg=5.0)
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [2, 1.01, 0], [3, 1.0, 0], [2, 1.0, 0]], float)
    d = corner_delays_us(p, t)
    np.testing.assert_allclose(d, [0, 50.0, 49.7, 0.0, 99.7, 0], atol=0.05)   # 1.1° is straight
    p2 = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0], [0, 0, 0]], float)
    np.testing.assert_allclose(corner_delays_us(p2, t), [0, 100.0, 0, 0])


def test_time_estimate_on_a_known_job():
    t = Timing(laser_on_delay_us=100, laser_off_delay_us=200, jump_delay_us=300,
               mark_delay_us=400, polygon_delay_us=180, min_corner_deg=5)
    job = make_job([np.array([[3.0, 4.0, 0.0], [13.0, 4.0, 0.0], [13.0, 14.0, 0.0]]),
                    np.array([[13.0, 14.0, 10.0], [13.0, 14.0, 30.0]])],
                   LaserParams(mark_speed_mm_s=100.0, jump_speed_mm_s=1000.0),
                   {1: LaserOverride(mark_speed_mm_s=50.0, jump_speed_mm_s=500.0)}, t)
    est = estimate_time(job)
    # jumps: origin → (3, 4, 0) = 5 mm at 1000 mm/s; → (13, 14, 10) = 10 mm at 500 mm/s
    # marks: 20 mm at 100 mm/s; 20 mm at 50 mm/s. Delays: 2 × 1000 µs + one 90° corner 90 µs
    assert est.jump_mm == pytest.approx(15.0)
    assert est.mark_mm == pytest.approx(40.0)
    assert est.jump_s == pytest.approx(0.005 + 0.02)
    assert est.mark_s == pytest.approx(0.2 + 0.4)
    assert est.delay_s == pytest.approx(2e-3 + 90e-6)
    assert est.total_s == pytest.approx(0.625 + 2.09e-3)
    assert est.paths == 2
    rest = estimate_time(job, first_path=1, start=(13.0, 14.0, 0.0))
    assert rest.total_s == pytest.approx(0.02 + 0.4 + 1e-3)


def test_points_from_arrays_are_rounded_and_read_only():
    job = make_job([np.array([[0.1234567891, 0, 0], [1, 1, 1]])])
    assert job.paths[0].points[0, 0] == 0.123457
    assert not job.paths[0].points.flags.writeable
    with pytest.raises(ValidationError, match=r"expected \(N, 3\) numbers"):
        MarkJob(paths=[{"points": np.zeros((3, 2))}])
