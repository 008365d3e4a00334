"""``insitu mark --pen/--pens`` and ``insitu job show``'s pens; pens in project files."""

import json

import pytest
from test_mark_cli import SQUARE, _cloud, _flat, _run

from insitu.errors import FormatError
from insitu.formats.pens import DEFAULT_PENS, Pen, PenTable, write_pens
from insitu.formats.project import Project, load_pens, read_project, write_project
from insitu.marking import PROJECTIONS, Placement, read_job


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("pens")
    (d / "rect.svg").write_text(SQUARE)
    _cloud(d / "step3.ply", -10, 10, -40, -20, 3.0)
    return d


def _mark(files, out, *extra):
    return _run("mark", "--cloud", files / "step3.ply", "--pattern", files / "rect.svg",
                "--at", 0, -30, "--width", 6, "--hatch", 0.5, "-o", out, *extra)


def test_pen_from_a_pens_file_with_an_option_overriding_it(files, tmp_path):
    pens = tmp_path / "pens.json"
    write_pens(pens, DEFAULT_PENS.replaced(Pen(name="etch", power_pct=55.0, passes=3)))
    out = tmp_path / "job.json"
    res = _mark(files, out, "--pens", pens, "--pen", "etch", "--speed", 250)
    assert res.exit_code == 0, res.output
    job = read_job(out)
    assert job.pens() == {"etch": list(range(len(job.paths)))}
    las = job.path_laser(0)
    assert (las.power_pct, las.mark_speed_mm_s, job.path_passes(0)) == (55.0, 250.0, 3)
    assert job.laser.mark_speed_mm_s == 250.0
    show = _flat(_run("job", "show", out).output)
    assert f"pen etch {len(job.paths)} paths: 55 %, 20 kHz, 250 mm/s" in show
    assert "3 passes" in show


def test_built_in_pens_without_a_file_and_the_old_options_alone(files, tmp_path):
    out = tmp_path / "deep.json"
    assert _mark(files, out, "--pen", "deep").exit_code == 0
    assert read_job(out).path_passes(0) == 2
    old = tmp_path / "old.json"
    assert _mark(files, old, "--power", 45).exit_code == 0
    job = read_job(old)
    assert job.paths[0].laser is None and job.laser.power_pct == 45.0
    assert job.laser.mark_speed_mm_s == 500.0
    assert " pen " not in _flat(_run("job", "show", old).output)


def test_an_unknown_pen_is_one_line_naming_the_pens(files, tmp_path):
    res = _mark(files, tmp_path / "x.json", "--pen", "laser")
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1
    assert "--pen: no pen 'laser'; the pens are 'mark', 'fine', 'deep' or 'bold'" in res.output
    assert not (tmp_path / "x.json").exists()


def test_project_keeps_its_pens_and_each_placements_pen(tmp_path):
    table = PenTable(default="b", pens=(Pen(name="a", passes=2), Pen(name="b", colour="#123456")))
    f = tmp_path / "p.insitu.json"
    write_project(f, Project(placements=(Placement('text:"A"', (0.0, 0.0), 5.0, pen="a"),),
                             pens=table))
    back = read_project(f, Placement, PROJECTIONS)
    assert back.pens == table and back.placements[0].pen == "a"
    assert load_pens(f) == table
    raw = json.loads(f.read_text())
    raw["placements"][0]["pen"] = "c"
    f.write_text(json.dumps(raw))
    with pytest.raises(FormatError, match=r"placements\[0\]\.pen: expected 'a' or 'b', got 'c'"):
        read_project(f, Placement, PROJECTIONS)
    raw["placements"][0]["pen"] = "a"
    raw["pens"][1]["frequency_khz"] = 0.5
    f.write_text(json.dumps(raw))
    with pytest.raises(FormatError, match=r"pens\[1\] \('b'\)\.frequency_khz: 0\.5 is outside"):
        read_project(f, Placement, PROJECTIONS)


def test_a_project_without_pens_reads_as_before(tmp_path):
    f = tmp_path / "p.insitu.json"
    write_project(f, Project())
    assert "pens" not in json.loads(f.read_text())
    assert read_project(f, Placement, PROJECTIONS).pens is None and load_pens(f) == DEFAULT_PENS
