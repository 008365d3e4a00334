"""Every file the program reads, fuzzed for a bounded time: the mutation engine of
tests/fuzzing.py (a few hundred examples over its twelve readers, in worker processes that
catch hangs and crashes), arbitrary bytes, arbitrary JSON, and valid files with one field
replaced by anything. A reader (and the first use of what it read) may only fail with an
InsituError. The run's seed is in pytest's header (tests/conftest.py draws one unless
INSITU_FUZZ_SEED=N repeats a run); INSITU_FUZZ_EXAMPLES=2000 explores longer (benchmarks/fuzz.py:
10,000 per reader)."""

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

import fuzzing
from insitu.calibrate.field_file import FieldCorrection, load_field_correction
from insitu.errors import InsituError
from insitu.formats.calibration import CameraCalibration, HeightCalibration
from insitu.formats.json_file import load_json_model, save_json_model
from insitu.formats.pointcloud import PointCloud, read_ply, write_ply
from insitu.formats.rig import RigConfig, ScanHeadConfig
from insitu.formats.sequence import Sequence
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import GalvoDriver, make_job, read_job, run_job, write_job
from insitu.marking.run import history
from insitu.services.common import camera_model
from insitu.services.field import read_targets_csv
from insitu.services.height import height_model
from insitu.vision.extract import CentreSettings

SEED = int(os.environ["INSITU_FUZZ_SEED"])         # the run's, set by tests/conftest.py
EXAMPLES = int(os.environ.get("INSITU_FUZZ_EXAMPLES", 60))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])
HEAD = TwoMirrorHead(350.0, 12.0)
RECORDED = Path(__file__).parents[1] / "data" / "scan-step-block-b4"

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.text(max_size=8)
    | st.floats(allow_nan=False, allow_infinity=False, width=32),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                 max_size=4),
    max_leaves=12)



@pytest.mark.parametrize("name", sorted(fuzzing.READERS))
def test_fuzz_engine(name):
    """Mutated valid files of each reader, as tests/fuzzing.py makes them (30 each)."""
    n = max(EXAMPLES // 2, 10)
    stats = fuzzing.run_reader(name, SEED, n, timeout_s=60.0)
    assert stats.examples == n and not stats.failures, (
        f"INSITU_FUZZ_SEED={SEED}: {stats.failures[:3]} (benchmarks/fuzz.py --readers {name} "
        f"--seed {SEED} --start K --examples 1 repeats example K)")
    assert stats.refused > 0                        # the mutations reach the readers' checks


def _job():
    return make_job([np.array([[0.0, 0.0, 0.0], [5.0, 1.0, 0.5]]),
                     np.array([[-3.0, 2.0, 1.0], [-3.0, 6.0, 1.0], [1.0, 6.0, 1.0]])])


def _height_calibration():
    cam = Sequence.open(RECORDED).camera
    return HeightCalibration(camera=cam, centres=CentreSettings().to_dict(), sheet={
        "pivot_height_mm": 350.0, "exponents": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
        "coefficients_mm": [0.0, 1.0, 0.5], "scale_mm": [100.0, 100.0, 50.0],
        "x_range_mm": [-50.0, 50.0], "z_range_mm": [-20.0, 20.0]})


def _field_correction():
    return FieldCorrection(method="table", field_size_mm=(200.0, 200.0),
                           region_mm=[-50.0, 50.0, -50.0, 50.0],
                           table={"x_nodes_mm": [-50.0, 0.0, 50.0],
                                  "y_nodes_mm": [-50.0, 0.0, 50.0],
                                  "values_mm": [[[0.1, 0.0]] * 3] * 3})


def _use_job(path):
    GalvoDriver(HEAD).compile(read_job(path))


def _use_progress(path):
    history(_job(), path, strict=True)


def _use_model(model, use=None):
    def reader(path):
        obj = load_json_model(path, model)
        if use is not None:
            use(obj)
    return reader


READERS = {
    # name: (write a valid sample to path, read and use it)
    "job": (lambda p: write_job(p, _job()), _use_job),
    "rig": (lambda p: p.write_text(json.dumps(
        {"kind": "rig", "camera": "opencv", "scan_head": "rtc", "stage": "grbl",
         "options": {"rtc": {"library": "librtc6.so", "k_bits_per_mm": 2000.0}}})),
        _use_model(RigConfig, lambda c: c.resolve(c.camera_calibration))),
    "camera-calibration": (lambda p: save_json_model(p, CameraCalibration(
        camera=Sequence.open(RECORDED).camera)),
        _use_model(CameraCalibration,
                   lambda c: camera_model(c.camera).project(np.array([[0.0, 0.0, 0.0]])))),
    "scan-head": (lambda p: save_json_model(p, ScanHeadConfig(
        pivot_height_mm=350.0, mirror_distance_mm=350.0, mirror_separation_mm=12.0,
        field_size_mm=(200.0, 200.0), z_range_mm=(-25.0, 25.0))),
        _use_model(ScanHeadConfig, lambda c: GalvoDriver.from_config(c).compile(_job()))),
    "height-calibration": (lambda p: save_json_model(p, _height_calibration()),
                           _use_model(HeightCalibration, height_model)),
    "field-correction": (lambda p: save_json_model(p, _field_correction()),
                         lambda p: load_field_correction(p).correct(
                             np.array([[0.0, 0.0], [20.0, -10.0]]))),
}


def _paths(value, prefix=()):
    """Every key path into a JSON value."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value[:3]):
            yield from _paths(v, prefix + (i,))


def _replace(value, path, new):
    if not path:
        return new
    value[path[0]] = _replace(value[path[0]], path[1:], new)
    return value


def _only_clear_errors(read, path):
    try:
        return read(path)
    except InsituError as e:
        assert str(e), "an error without a message"
    return None


def _finite_pattern(path):
    from insitu.patterns.load import load_pattern
    p = load_pattern(str(path))
    for line in p.contours + p.paths:
        assert np.isfinite(line).all(), f"{path.name}: non-finite coordinates accepted"


@pytest.fixture(scope="module")
def samples(tmp_path_factory):
    folder = tmp_path_factory.mktemp("valid")
    out = {}
    for name, (write, read) in READERS.items():
        path = folder / f"{name}.json"
        write(path)
        read(path)                                   # the valid sample reads cleanly
        out[name] = json.loads(path.read_text())
    return out


@pytest.mark.parametrize("name", sorted(READERS))
@FUZZ
@seed(SEED)
@given(data=st.data())
def test_fuzz_mutated_valid_file(name, samples, tmp_path, data):
    valid = samples[name]
    paths = list(_paths(valid))
    where = data.draw(st.sampled_from(paths), label="field")
    value = _replace(json.loads(json.dumps(valid)), where, data.draw(json_values, label="value"))
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(value))
    _only_clear_errors(READERS[name][1], path)


@pytest.mark.parametrize("name", sorted(READERS))
@FUZZ
@seed(SEED)
@given(raw=st.binary(max_size=120) | json_values.map(lambda v: json.dumps(v).encode()))
def test_fuzz_arbitrary_content(name, tmp_path, raw):
    path = tmp_path / f"{name}.json"
    path.write_bytes(raw)
    _only_clear_errors(READERS[name][1], path)


@FUZZ
@seed(SEED)
@given(raw=st.binary(max_size=200) | json_values.map(lambda v: json.dumps(v).encode()))
def test_fuzz_progress_file(tmp_path, raw):
    path = tmp_path / "job.progress.json"
    path.write_bytes(raw)
    _only_clear_errors(_use_progress, path)


@FUZZ
@seed(SEED)
@given(data=st.data())
def test_fuzz_mutated_progress_file(tmp_path, data):
    path = tmp_path / "job.progress.json"
    from insitu.devices.galvo import RecordingController
    run_job(_job(), GalvoDriver(HEAD), RecordingController(), path)
    rec = json.loads(path.read_text())
    key = data.draw(st.sampled_from(sorted(rec)))
    rec[key] = data.draw(json_values)
    path.write_text(json.dumps(rec))
    _only_clear_errors(_use_progress, path)


@FUZZ
@seed(SEED)
@given(text=st.text(alphabet="xy,.-+eE0123456789 \n\tinfa", max_size=80))
def test_fuzz_targets_csv(tmp_path, text):
    path = tmp_path / "targets.csv"
    path.write_text(text)
    _only_clear_errors(read_targets_csv, path)


@FUZZ
@seed(SEED)
@given(cut=st.integers(0, 400), flip=st.lists(st.tuples(st.integers(0, 400),
                                                        st.integers(0, 255)), max_size=4))
def test_fuzz_point_cloud(tmp_path, cut, flip):
    good = tmp_path / "good.ply"
    if not good.exists():
        pts = np.random.default_rng(0).uniform(-5, 5, (20, 3))
        write_ply(good, PointCloud(pts, {"intensity": np.linspace(0, 1, 20)}))
    raw = bytearray(good.read_bytes())[:cut or None]
    for at, b in flip:
        if at < len(raw):
            raw[at] = b
    path = tmp_path / "cloud.ply"
    path.write_bytes(bytes(raw))
    try:
        cloud = read_ply(path)
    except InsituError:
        return
    assert cloud.points.shape[1] == 3 and not math.isnan(float(len(cloud)))


def test_ply_header_that_crashed_open3d(tmp_path):
    """Found by the fuzzer: Open3D's reader killed the process on this header."""
    path = tmp_path / "cut.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\ncomment")
    with pytest.raises(InsituError, match="incomplete PLY header"):
        read_ply(path)


# ---------------------------------------------------------------- patterns, structure-aware
# (test_patterns.py throws random bytes at the loaders; these keep the file well-formed and
# put anything into the values the loaders interpret)
_svg_value = st.one_of(st.text(alphabet="0123456789.-+eE ,MmLlHhVvCcSsQqTtAaZz()%", max_size=30),
                       st.sampled_from(["1e308", "-0", "nan", "inf", "0", "1e-320", "100%",
                                        "matrix(0 0 0 0 0 0)", "scale(0)", "none", "#fff"]))


@settings(FUZZ, max_examples=max(FUZZ.max_examples // 3, 10))
@seed(SEED)
@given(d=_svg_value, transform=_svg_value, width=_svg_value, view=_svg_value,
       fill=st.sampled_from(["black", "white", "none", "#000", "red"]),
       stroke=st.sampled_from(["black", "none", "#111"]), sw=_svg_value)
def test_fuzz_svg_values(tmp_path, d, transform, width, view, fill, stroke, sw):
    svg = (f"<svg xmlns='http://www.w3.org/2000/svg' width='{width}' height='40mm' "
           f"viewBox='{view}'><g transform='{transform}'><path d='{d}' fill='{fill}' "
           f"stroke='{stroke}' stroke-width='{sw}'/><rect x='1' y='1' width='{width}' "
           f"height='5' transform='{transform}'/></g></svg>")
    path = tmp_path / "fuzz.svg"
    path.write_text(svg)
    _only_clear_errors(_finite_pattern, path)


@pytest.fixture(scope="module")
def dxf_lines(tmp_path_factory):
    import ezdxf
    doc = ezdxf.new()
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (10, 0), (10, 5), (0, 5)], close=True)
    msp.add_circle((20, 20), 3)
    msp.add_arc((0, 20), 4, 10, 200)
    msp.add_line((-5, -5), (5, 8))
    msp.add_spline([(0, 0), (3, 4), (6, -1), (9, 3)])
    path = tmp_path_factory.mktemp("dxf") / "valid.dxf"
    doc.saveas(path)
    return path.read_text().splitlines()


@settings(FUZZ, max_examples=max(FUZZ.max_examples // 3, 10))
@seed(SEED)
@given(data=st.data())
def test_fuzz_dxf_values(tmp_path, dxf_lines, data):
    lines = list(dxf_lines)
    entities = lines.index("ENTITIES")
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(entities + 1, len(lines) - 1))
        if i % 2 == entities % 2:             # a value line (group codes sit on the others)
            lines[i] = data.draw(st.sampled_from(["1e308", "-1e308", "nan", "0", "-1", "1e400",
                                                  "abc", "", "999999999", "0.000001", "1e12"]))
    path = tmp_path / "fuzz.dxf"
    path.write_text("\n".join(lines) + "\n")
    _only_clear_errors(_finite_pattern, path)
