"""Plausibility bounds (formats/bounds.py): every value of issue 16's list is refused with one
line naming the option or field, the value and the range — exit 1, within a second, nothing
written — and user text (file names, pattern specs) is printed as it is, never as rich markup."""

import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.errors import InsituError
from insitu.formats.bounds import BOUNDS, check
from insitu.formats.pointcloud import PointCloud, write_ply

runner = CliRunner()
DATA = Path(__file__).parents[1] / "data"
JOB = {"paths": [{"points": [[0, 0, 0], [1, 0, 0]]}]}


def _refused(tmp_path, args, *words):
    """Run ``args``; it must exit 1 (SystemExit, not an uncaught exception) within a second of
    this process's CPU time (wall time on a shared CI machine swings eightfold) with one line
    holding every word, and leave no file in ``tmp_path/out``."""
    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    args = [str(a).format(tmp=tmp_path, out=out) for a in args]
    t0 = time.process_time()
    res = runner.invoke(app, args)
    seconds = time.process_time() - t0
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1, (res.exception, res.output)
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    for w in words:
        assert w in lines[0], lines[0]
    assert seconds < 1.0, f"{seconds:.2f} s"
    assert list(out.iterdir()) == []
    return lines[0]


def test_the_table_is_sound_and_the_defaults_lie_within_it():
    from insitu.marking import LaserParams
    from insitu.marking.job import Timing
    from insitu.sim.rig import NOMINAL_HEAD

    for name, b in BOUNDS.items():
        assert b.lo < b.hi and b.why, name
    for model in (LaserParams(), Timing(), NOMINAL_HEAD):       # validated on construction
        assert model.model_dump()
    assert check("power_pct", 100, "x") == 100
    assert BOUNDS["seed"].problem(10**400) == "inf is outside 0 … 4294967295"
    with pytest.raises(InsituError, match=r"^--x: nan is outside 0 … 100 %$"):
        check("power_pct", float("nan"), "--x")


@pytest.mark.parametrize("args, words", [
    (("scan", "-o", "{out}/c.ply", "--binning", 0), ["--binning: 0 is outside 1 … 16"]),
    (("scan", "-o", "{out}/c.ply", "--spacing", "nan"), ["--spacing: nan is outside", "mm"]),
    (("scan", "-o", "{out}/c.ply", "--seed", -1), ["--seed: -1 is outside 0 … 4294967295"]),
    (("sim", "record", "scan", "-o", "{out}/r", "--seed", -1), ["--seed: -1"]),
    (("gui", "--binning", 0), ["--binning: 0 is outside"]),
    (("mark", "--cloud", "{tmp}/c.ply", "--pattern", "qr:x", "--at", 0, 0, "-o", "{out}/j.json",
      "--rotate", "inf"), ["--rotate: inf is outside -3600 … 3600 °"]),
    (("mark", "--cloud", "{tmp}/c.ply", "--pattern", "qr:x", "--at", "nan", 0, "-o",
      "{out}/j.json"), ["--at: nan is outside -1000 … 1000 mm"]),
    (("mark", "--cloud", "{tmp}/c.ply", "--pattern", "qr:x", "--at", 0, 0, "-o", "{out}/j.json",
      "--speed", 1e-300), ["--speed: 1e-300 is outside 0.1 … 20000 mm/s"]),
    (("mark", "--cloud", "{tmp}/c.ply", "--pattern", "qr:x", "--at", 0, 0, "-o", "{out}/j.json",
      "--jump-speed", 1e308), ["--jump-speed: 1e+308 is outside 1 … 50000 mm/s"]),
    (("mark", "--cloud", "{tmp}/c.ply", "--pattern", "qr:x", "--at", 0, 0, "-o", "{out}/j.json",
      "--width", 0), ["--width: 0 is outside 0.001 … 2000 mm"]),
    (("job", "run", "{tmp}/j.json", "--seed", -1), ["--seed: -1"]),
    (("calibrate", "field", "{tmp}/rec", "-o", "{out}/f.json", "--sigma", "inf"), ["--sigma: inf"]),
])
def test_options_out_of_bounds(tmp_path, args, words):
    _refused(tmp_path, args, *words)


@pytest.mark.parametrize("laser, words", [
    ({"mark_speed_mm_s": 1e-300}, ["laser.mark_speed_mm_s: 1e-300 is outside 0.1 … 20000 mm/s"]),
    ({"mark_speed_mm_s": 1e308}, ["laser.mark_speed_mm_s: 1e+308 is outside"]),
    ({"frequency_khz": 1e-300}, ["laser.frequency_khz: 1e-300 is outside 1 … 4000 kHz"]),
    ({"power_pct": 100.5}, ["laser.power_pct: 100.5 is outside 0 … 100 %"]),
])
def test_job_file_laser_out_of_bounds(tmp_path, laser, words):
    (tmp_path / "job.json").write_text(json.dumps({**JOB, "laser": laser}))
    _refused(tmp_path, ("job", "show", "{tmp}/job.json"), "job.json", *words)


def test_job_file_path_laser_and_timing_out_of_bounds(tmp_path):
    job = {"timing": {"jump_delay_us": 1e9},
           "paths": [{"points": [[0, 0, 0], [1, 0, 0]], "laser": {"jump_speed_mm_s": 1e-3}}]}
    (tmp_path / "job.json").write_text(json.dumps(job))
    _refused(tmp_path, ("job", "show", "{tmp}/job.json"),
             "timing.jump_delay_us: 1e+09 is outside 0 … 100000 µs (and 1 more)")


@pytest.fixture(scope="module")
def calib(tmp_path_factory):
    """The simulated rig's files (``insitu sim calib``), each broken one way in a copy."""
    d = tmp_path_factory.mktemp("calib")
    assert runner.invoke(app, ["sim", "calib", "-o", str(d)]).exit_code == 0
    rig = json.loads((d / "rig.json").read_text())

    def edited(src: str, dst: str, edit) -> str:
        data = json.loads((d / src).read_text())
        edit(data)
        (d / dst).write_text(json.dumps(data))
        return dst

    rigs = {
        "pivot": {"scan_head_config": edited("scan-head.json", "h1.json",
                                             lambda h: h.update(pivot_height_mm=1e-300))},
        "separation": {"scan_head_config": edited("scan-head.json", "h2.json",
                                                  lambda h: h.update(mirror_separation_mm=1e300))},
        "k1": {"camera_calibration": edited("camera.json", "c1.json",
                                            lambda c: c["camera"]["dist"].__setitem__(0, 1e300))},
        "bits0": {"scan_head": "lmc", "options": {"lmc": {"bits_per_deg": 0}}},
        "bits-": {"scan_head": "lmc", "options": {"lmc": {"bits_per_deg": -1500}}},
        "rtc-k": {"scan_head": "rtc", "options": {"rtc": {"library": "none.so",
                                                          "correction_file": "none.ct5",
                                                          "k_bits_per_mm": 1e-300}}},
    }
    for name, change in rigs.items():
        (d / f"rig-{name}.json").write_text(json.dumps({**rig, **change}))
    return d


@pytest.mark.parametrize("name, words", [
    ("pivot", ["h1.json: pivot_height_mm: 1e-300 is outside 1 … 2000 mm"]),
    ("separation", ["h2.json: mirror_separation_mm: 1e+300 is outside 0 … 200 mm"]),
    ("k1", ["c1.json: camera.dist[0]: k1 = 1e+300 is outside -10 … 10"]),
    ("bits0", ["rig-bits0.json: options.lmc.bits_per_deg: 0 is outside 10 … 100000 bits/°"]),
    ("bits-", ["options.lmc.bits_per_deg: -1500 is outside"]),
    ("rtc-k", ["options.rtc.k_bits_per_mm: 1e-300 is outside 1 … 1000000 bits/mm"]),
])
def test_rig_files_out_of_bounds(calib, tmp_path, name, words):
    _refused(tmp_path, ("scan", "--rig", calib / f"rig-{name}.json", "-o", "{out}/c.ply",
                        "--region", -5, 5, -5, 5), *words)


def _height_calibration(tmp_path, **sheet) -> Path:
    rec = json.loads((DATA / "height-cal-b4" / "sequence.json").read_text())
    base = {"pivot_height_mm": 350.0, "exponents": [[0, 0, 0], [1, 0, 0]],
            "coefficients_mm": [0.0, 0.0], "scale_mm": [100.0, 100.0, 25.0],
            "x_range_mm": [-20.0, 20.0], "z_range_mm": [0.0, 20.0]}
    path = tmp_path / "hcal.json"
    path.write_text(json.dumps({"kind": "height-calibration", "camera": rec["camera"],
                                "sheet": {**base, **sheet}}))
    return path


@pytest.mark.parametrize("sheet, words", [
    ({"exponents": [[0, 0, 0], [-1, 0, 0]]}, ["sheet.exponents[1][0]: -1 is outside 0 … 12"]),
    ({"coefficients_mm": [0.0, 1e300]}, ["sheet.coefficients_mm[1]: 1e+300 is outside"]),
    ({"pivot_height_mm": 1e-300}, ["sheet.pivot_height_mm: 1e-300 is outside 1 … 2000 mm"]),
])
def test_height_calibration_out_of_bounds(tmp_path, sheet, words):
    hcal = _height_calibration(tmp_path, **sheet)
    _refused(tmp_path, ("scan", "--replay", DATA / "scan-step-block-b4", "--height-cal", hcal,
                        "-o", "{out}/c.ply"), "hcal.json", *words)


def test_a_good_height_calibration_passes_the_bounds(tmp_path):
    from insitu.formats.calibration import HeightCalibration
    from insitu.formats.json_file import load_json_model

    assert load_json_model(_height_calibration(tmp_path), HeightCalibration).sheet.exponents


def test_field_correction_out_of_bounds(tmp_path):
    from pydantic import ValidationError

    from insitu.calibrate.field_file import RBFSpec

    good = {"sigma_mm": 20.0, "mse_goal_mm2": 1e-4, "centres_mm": [[0, 0]],
            "weights_mm": [[0.1, 0.0]], "bias_mm": [0, 0]}
    assert RBFSpec.model_validate(good).sigma_mm == 20.0
    for key, value, word in (("sigma_mm", 1e-300, "1e-300 is outside 0.001 … 10000 mm"),
                             ("weights_mm", [[1e300, 0]], "1e+300 is outside -1000000 … 1000000 mm"),
                             ("centres_mm", [[0, -1e9]], "-1e+09 is outside -1000 … 1000 mm")):
        with pytest.raises(ValidationError, match=rf"{key}\n  {re.escape(word)}"):
            RBFSpec.model_validate({**good, key: value})


# -- user text is printed as it is -------------------------------------------------------------

def test_a_file_name_with_markup_is_printed_as_it_is(tmp_path):
    folder = tmp_path / "a["
    folder.mkdir()
    job = folder / "]b.json"                                 # the path reads .../a[/]b.json
    line = _refused(tmp_path, ("job", "show", job), "a[/]b.json: no such job file")
    assert line == f"error: {job}: no such job file"
    job.write_text(json.dumps(JOB))
    res = runner.invoke(app, ["job", "show", str(job)])
    assert res.exit_code == 0 and res.exception is None, res.output
    assert "a[/]b.json" in "".join(res.output.split())       # the title may wrap


def test_a_pattern_spec_is_printed_as_it_is(tmp_path):
    g = np.meshgrid(np.arange(-10, 10.01, 0.2), np.arange(-40, -19.99, 0.2))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    write_ply(tmp_path / "c.ply", PointCloud(np.column_stack([xy, np.full(len(xy), 3.0)])))
    res = runner.invoke(app, ["mark", "--cloud", str(tmp_path / "c.ply"), "--pattern", 'qr:"x"',
                              "--at", "0", "-30", "--width", "8", "-o", str(tmp_path / "j.json")])
    assert res.exit_code == 0 and res.exception is None, res.output
    assert "qr:x:" in res.output and "❌" not in res.output


# -- the other files and options -----------------------------------------------------------

@pytest.mark.parametrize("edit, words", [
    (lambda p: p["placements"][0].update(width_mm=1e300),
     "placements[0].width_mm: 1e+300 is outside"),
    (lambda p: p["placements"][0].update(at_mm=[0, -1e9]),
     "placements[0].at_mm[1]: -1e+09 is outside"),
    (lambda p: p["scan"].update(spacing_mm=1e-300), "scan.spacing_mm: 1e-300 is outside"),
    (lambda p: p["rig"].update(binning=0), "rig.binning: 0 is outside 1 … 16"),
    (lambda p: p["rig"].update(seed=-1), "rig.seed: -1 is outside"),
])
def test_project_file_out_of_bounds(tmp_path, edit, words):
    from insitu.errors import FormatError
    from insitu.formats.project import read_project

    project = {"format": "insitu-project/1", "schema_version": 1, "rig": {}, "scan": {},
               "placements": [{"pattern": "qr:x", "at_mm": [0, 0], "width_mm": 8}]}
    path = tmp_path / "p.insitu.json"
    path.write_text(json.dumps(project))
    assert read_project(path, lambda *a: a, ["planar"]).placements[0][2] == 8     # width_mm
    edit(project)
    path.write_text(json.dumps(project))
    with pytest.raises(FormatError) as info:
        read_project(path, lambda *a: a, ["planar"])
    assert "\n" not in str(info.value) and words in str(info.value), str(info.value)


def test_stage_and_projection_options_out_of_bounds():
    from insitu.devices.projection import GalvoLineProjector
    from insitu.devices.stage_grbl import GrblStage
    from insitu.errors import ConfigError
    from insitu.geometry.beams import TwoMirrorHead

    with pytest.raises(ConfigError, match=r"^options.stage.feed_mm_min: 0 is outside 1 … "):
        GrblStage("loop://", feed_mm_min=0, open_port=None)        # refused before the port
    head = TwoMirrorHead(350.0, 12.0)
    with pytest.raises(ConfigError, match=r"^options.projection.speed_mm_s: 1e-300 is outside"):
        GalvoLineProjector(None, head, (100, 100), (-5, 5), speed_mm_s=1e-300)


def test_checkerboard_out_of_bounds():
    from pydantic import ValidationError

    from insitu.formats.sequence import CheckerboardSpec

    assert CheckerboardSpec(cols=9, rows=6, square_mm=10).cols == 9
    with pytest.raises(ValidationError, match=r"square_mm\n  1e-300 is outside 0.001 … 2000 mm"):
        CheckerboardSpec(cols=9, rows=6, square_mm=1e-300)


@pytest.mark.parametrize("board, charuco, words", [
    ("99999x6x25", None, "--board '99999x6x25': columns 99999 is outside 2 … 200"),
    ("9x6x0", None, "--board '9x6x0': square side 0 is outside 0.001 … 2000 mm"),
    ("9x6x25", "DICT_4X4_50:1e300", "--charuco 'DICT_4X4_50:1e300': marker side 1e+300 is outside"),
])
def test_board_text_out_of_bounds(board, charuco, words):
    """The core names the field in words; the command shows its option."""
    from insitu.calibrate.photos import parse_board
    from insitu.cli.common import as_option
    from insitu.errors import CalibrationError

    assert parse_board("9x6x25").cols == 9
    with pytest.raises(CalibrationError) as info:
        parse_board(board, charuco)
    assert str(info.value).startswith(words.removeprefix("--")), str(info.value)
    assert as_option(info.value).startswith(words), as_option(info.value)


def test_camera_options_out_of_bounds_before_anything_opens(tmp_path):
    from insitu.devices.camera_genicam import GenICamCamera
    from insitu.devices.camera_opencv import OpenCVCamera
    from insitu.errors import ConfigError

    with pytest.raises(ConfigError, match=r"^options.camera.exposure_ms: 1e\+300 is outside"):
        OpenCVCamera(str(tmp_path / "none.png"), exposure_ms=1e300)
    with pytest.raises(ConfigError, match=r"^options.camera.resolution: 0 is outside 1 … "):
        OpenCVCamera(str(tmp_path / "none.png"), resolution=(0, 480))
    with pytest.raises(ConfigError, match=r"^options.camera.gain_db: 1000 is outside -20 … 60"):
        GenICamCamera(tmp_path / "none.cti", gain_db=1000)
