"""Each variation point is one table that the loader, the CLI and the files read; and every
safety refusal carries the place it refused (SafetyError.where_mm)."""

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.calibrate.field import RBFNetwork
from insitu.calibrate.field_file import (
    FIELD_METHODS,
    FieldCorrection,
    load_field_correction,
    model_spec,
)
from insitu.cli.main import app
from insitu.devices.protocols import check_in_field as head_check
from insitu.errors import ConfigError, FormatError, SafetyError
from insitu.formats.project import Project, read_project, write_project
from insitu.formats.validation import one_of
from insitu.geometry.beams import TwoMirrorHead
from insitu.geometry.field import check_in_field
from insitu.marking import (
    PROJECTIONS,
    GalvoDriver,
    Limits,
    Placement,
    check_projection,
    check_targets,
    make_job,
    project,
)
from insitu.patterns import FILE_SUFFIXES, SOURCES, SPEC_PREFIXES, is_spec, load_pattern
from insitu.reconstruct.height_models import HEIGHT_MODELS, HeightModel
from insitu.services import height_model, load_height_calibration
from insitu.vision.centres import CENTRE_METHODS, line_centres
from insitu.vision.extract import CentreSettings, extract_centres

DATA = Path(__file__).parents[1] / "data"
SAMPLES = Path(__file__).parents[2] / "patterns"
runner = CliRunner()


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def _flat(x0, x1, y0, y1, z=lambda x, y: np.full_like(x, 3.0), step=0.2):
    X, Y = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    return np.column_stack([X.ravel(), Y.ravel(), z(X.ravel(), Y.ravel())])


# -- the tables ---------------------------------------------------------------------------
def test_one_of_lists_a_tables_keys():
    assert one_of(PROJECTIONS) == "'planar' or 'wrap'"
    assert one_of(CENTRE_METHODS) == "'gray', 'gaussian' or 'steger'"
    assert one_of(["only"]) == "'only'"


@pytest.mark.parametrize("args, table", [
    (("mark", "--cloud", "c.ply", "--pattern", "qr:x", "--at", 0, 0, "--width", 5,
      "-o", "{tmp}/j.json", "--mode", "cone"), PROJECTIONS),
    (("scan", "-o", "{tmp}/c.ply", "--replay", DATA / "scan-step-block-b4",
      "--height-model", "spline"), HEIGHT_MODELS),
    (("calibrate", "field", DATA, "-o", "{tmp}/f.json", "--method", "spline"), FIELD_METHODS),
])
def test_the_commands_accept_exactly_the_tables_keys(tmp_path, args, table):
    res = _run(*[str(a).format(tmp=tmp_path) for a in args])
    assert res.exit_code == 1
    assert f"expected {one_of(table)}" in res.output


@pytest.mark.parametrize("command, option, table", [
    ("mark", "--mode", PROJECTIONS), ("scan", "--height-model", HEIGHT_MODELS),
    ("calibrate field", "--method", FIELD_METHODS)])
def test_the_help_names_every_choice(command, option, table):
    res = runner.invoke(app, command.split() + ["--help"], env={"COLUMNS": "400"})
    assert res.exit_code == 0
    line = next(ln for ln in res.output.splitlines() if ln.strip("│ ").startswith(option))
    assert all(f"{k} (" in line or f"{k}: " in line for k in table), line


def test_the_mark_help_lists_every_pattern_source():
    res = runner.invoke(app, ["mark", "--help"], env={"COLUMNS": "1000"})
    line = next(ln for ln in res.output.splitlines() if ln.strip("│ *").startswith("--pattern"))
    assert all(src.usage in line for src in SOURCES.values())


def test_the_loader_dispatches_on_the_pattern_sources(tmp_path):
    assert SPEC_PREFIXES == ("text:", "qr:", "datamatrix:", "microqr:", "code128:", "fiducials:")
    assert {".svg", ".dxf", ".png", ".webp"} <= set(FILE_SUFFIXES)
    assert all(is_spec(p + "x") for p in SPEC_PREFIXES) and not is_spec("logo.svg")
    assert load_pattern(str(SAMPLES / "logo.svg")).contours
    assert load_pattern("fiducials:2x3").size == pytest.approx((11.0, 6.0))
    (tmp_path / "a.xyz").write_text("x")
    with pytest.raises(FormatError, match=r"expected \.svg, \.svgz, \.dxf, \.png, .*\.webp\)"):
        load_pattern(str(tmp_path / "a.xyz"))
    with pytest.raises(FormatError, match=r"unknown option 'colour' \(allowed: ec, quiet, invert"):
        load_pattern("qr:x;colour=red")


def test_project_files_take_the_projection_modes(tmp_path):
    path = tmp_path / "p.insitu.json"
    for mode in PROJECTIONS:
        placement = Placement('qr:"a"', (0.0, 0.0), 5.0, mode=mode)
        write_project(path, Project(placements=(placement,)))
        assert read_project(path, Placement, PROJECTIONS).placements[0].mode == mode
    data = json.loads(path.read_text())
    data["placements"][0]["mode"] = "cone"
    path.write_text(json.dumps(data))
    with pytest.raises(FormatError, match=rf"placements\[0\]\.mode: expected "
                                          rf"{one_of(PROJECTIONS)}, got 'cone'"):
        read_project(path, Placement, PROJECTIONS)


def test_placements_and_project_refuse_an_unknown_mode():
    cloud = _flat(-5, 5, -5, 5)
    with pytest.raises(FormatError, match=rf"mode 'cone': expected {one_of(PROJECTIONS)}"):
        Placement('qr:"a"', (0.0, 0.0), 5.0, mode="cone").placed()
    with pytest.raises(FormatError, match="mode 'cone'"):
        project([np.array([[0.0, 0.0], [1.0, 0.0]])], cloud, "cone")
    for name, mode in PROJECTIONS.items():
        proj = project([np.array([[-2.0, 0.0], [2.0, 0.0]])], cloud, name, anchor=(0.0, 0.0))
        assert proj.mode == name and np.allclose(proj.points[:, 2], 3.0)
        assert mode.project is not None and mode.description


def test_height_models_follow_the_protocol(height_cal_file):
    cal = load_height_calibration(height_cal_file)
    for name, kind in HEIGHT_MODELS.items():
        _, model = height_model(cal, name)
        assert isinstance(model, HeightModel) and isinstance(model, kind.model)
        assert model.name == name
        lo, hi = model.z_range
        assert lo < hi
        again = kind.model.from_dict(model.to_dict())
        assert again.z_range == pytest.approx(model.z_range)
    with pytest.raises(ConfigError, match=rf"height model 'spline': expected "
                                          rf"{one_of(HEIGHT_MODELS)}"):
        height_model(cal, "spline")


@pytest.mark.parametrize("field, value", [("model", "spline"), ("centres.method", "canny")])
def test_a_height_file_names_a_model_and_a_centre_method_of_the_tables(height_cal_file,
                                                                         tmp_path, field, value):
    data = json.loads(height_cal_file.read_text())
    where = data
    *head, last = field.split(".")
    for key in head:
        where = where[key]
    where[last] = value
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    table = HEIGHT_MODELS if field == "model" else CENTRE_METHODS
    with pytest.raises(ConfigError) as e:
        load_height_calibration(path)
    assert str(e.value) == f"{path}: {field}: expected {one_of(table)}, got {value!r}"


def _line_image(v0=40.3, H=96, W=120):
    rows = np.arange(H)[:, None]
    line = 20 + 200 * np.exp(-0.5 * ((rows - v0) / 1.6) ** 2)
    return np.broadcast_to(line, (H, W)).astype(np.uint8)


def test_every_centre_method_finds_the_line():
    img = _line_image()
    for name, method in CENTRE_METHODS.items():
        c = line_centres(img, name, direction="rows")
        assert len(c) > 100 and abs(np.median(c.v) - 40.3) < 0.2, name
        assert set(method.options) <= set(CentreSettings.__dataclass_fields__)
        s = extract_centres(img, CentreSettings(method=name, smooth_half_window=0))
        assert abs(np.median(s.v) - 40.3) < 0.2
        if not method.options:                   # the settings change nothing else
            assert np.allclose(s.v, c.v)
    with pytest.raises(ConfigError, match=rf"centre method 'canny': expected "
                                          rf"{one_of(CENTRE_METHODS)}"):
        CentreSettings(method="canny")


def test_field_methods_are_the_files_methods(tmp_path):
    shift = RBFNetwork(np.zeros((1, 2)), np.zeros((1, 2)), np.array([-3.0, 0.0]), 30.0)
    fc = FieldCorrection(method="rbf", field_size_mm=[200.0, 200.0],
                         region_mm=[-90.0, 90.0, -90.0, 90.0], **model_spec(shift))
    assert isinstance(fc.delta(), FIELD_METHODS["rbf"].model_type)
    assert fc.rbf.summary() == "RBF: σ = 30 mm, MSE goal 0 mm², 1 neurons"
    data = fc.model_dump(mode="json")
    data["method"] = "spline"
    path = tmp_path / "f.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=rf"method: expected {one_of(FIELD_METHODS)}, "
                                          "got 'spline'"):
        load_field_correction(path)


# -- one field check, and where a refusal happened -----------------------------------------
def test_the_field_check():
    pts = np.array([[0.0, 0.0], [100.0, -100.0], [150.0, 0.0], [101.0, 0.0], [np.nan, 0.0]])
    check_in_field(pts[:2], (200.0, 200.0), lambda i, f: "never")
    with pytest.raises(SafetyError) as e:
        check_in_field(pts, (200.0, 200.0), lambda i, f: f"point {i} outside {f}", more=True)
    assert str(e.value) == "point 2 outside ±100 × ±100 mm (and 2 more points)"
    assert e.value.where_mm == (150.0, 0.0)
    with pytest.raises(SafetyError) as e:
        check_in_field(pts[:4], (200.0, 200.0), lambda i, f: f"point {i}", worst=True,
                       at=pts[:4] + 1)
    assert str(e.value) == "point 2" and e.value.where_mm == (151.0, 1.0)
    with pytest.raises(SafetyError) as e:
        check_in_field(pts[4:], (200.0, 200.0), lambda i, f: f"point {i}")
    assert e.value.where_mm is None                   # not finite: refused, no place to show


def test_refusals_carry_where_they_happened():
    limits = Limits()

    def where(fn, *args):
        with pytest.raises(SafetyError) as e:
            fn(*args)
        return e.value.where_mm

    # field (projection), outside the scanned area
    proj = project([np.array([[95.0, 0.0], [104.0, 0.0]])], _flat(90, 110, -5, 5))
    assert where(check_projection, proj, limits)[0] > 100.0
    assert where(project, [np.array([[45.0, 0.0], [55.0, 0.0]])],
                 _flat(-10, 10, -10, 10)) == pytest.approx((50.0, 0.0))
    # focus range
    proj = project([np.array([[0.0, 0.0], [9.0, 0.0]])],
                   _flat(-10, 10, -10, 10, lambda x, y: 20 + 0.5 * x))
    assert where(check_projection, proj, Limits(z_range_mm=(-25.0, 24.0))) == \
        pytest.approx((9.0, 0.0))
    # hole
    cloud = _flat(-15, 15, -15, 15)
    cloud = cloud[np.hypot(cloud[:, 0] - 4.0, cloud[:, 1] - 2.0) > 2.5]
    x, y = where(check_projection, project([np.array([[-10.0, 2.0], [10.0, 2.0]])], cloud), limits)
    assert 1.0 <= x <= 7.0 and y == pytest.approx(2.0)
    # wall
    chamfer = _flat(-10, 10, -10, 10, lambda x, y: np.clip(np.tan(np.radians(70)) * y, 0, 5), 0.1)
    x, y = where(check_projection, project([np.array([[3.0, -5.0], [3.0, 5.0]])], chamfer), limits)
    assert x == pytest.approx(3.0) and 0.0 <= y <= 2.0
    # field through the head, at height: the target's place, not the beam's
    head = TwoMirrorHead(350.0, 12.0)
    assert where(check_targets, np.array([[97.0, 0.0, 20.0]]), Limits(head=head)) == (97.0, 0.0)
    # the driver's corrected commands
    driver = GalvoDriver(head, Limits((200.0, 200.0)), correction=lambda q: q * 1.1)
    assert where(driver.check, make_job([np.array([[95.0, 1.0, 0.0], [96.0, 1.0, 0.0]])])) \
        == pytest.approx((95.0, 1.0))
    # the field correction's targets and commands, the scan head's points
    shift = RBFNetwork(np.zeros((1, 2)), np.zeros((1, 2)), np.array([-3.0, 0.0]), 30.0)
    fc = FieldCorrection(method="rbf", field_size_mm=[200.0, 200.0],
                         region_mm=[-90.0, 90.0, -90.0, 90.0], **model_spec(shift))
    assert where(fc.correct, np.array([[0.0, 0.0], [120.0, 0.0]])) == (120.0, 0.0)
    assert where(fc.correct, np.array([[99.0, 4.0]])) == (99.0, 4.0)
    assert where(head_check, (200.0, 200.0), (0.0, 0.0), (0.0, 105.0)) == (0.0, 105.0)
