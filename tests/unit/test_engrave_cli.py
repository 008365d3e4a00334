"""``insitu engrave`` refuses bad input with one line, the laser off and nothing written."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from insitu.cli.main import app
from insitu.formats.pointcloud import PointCloud, write_ply

runner = CliRunner()
SQUARE = ('<svg xmlns="http://www.w3.org/2000/svg" width="2mm" height="2mm" viewBox="0 0 2 2">'
          '<rect width="2" height="2"/></svg>')


def _cloud(path, x0, x1, y0, y1, z, step=0.25):
    g = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    xy = np.column_stack([g[0].ravel(), g[1].ravel()])
    write_ply(path, PointCloud(np.column_stack([xy, np.full(len(xy), z)])))
    return path


@pytest.mark.parametrize("args, message", [
    (("--material", "glass"), "--material: no material 'glass'; the materials are "
                              "'stainless-steel'"),
    (("--depth", "8"), "depth 8 mm is beyond reach in stainless-steel: 1396 passes"),
    (("--depth", "30"), "--depth: 30 is outside"),
    (("--at", "98", "0"), "outside the scan field"),
])
def test_bad_input_is_refused_in_one_line_and_nothing_is_written(tmp_path, args, message):
    (tmp_path / "sq.svg").write_text(SQUARE)
    cloud = _cloud(tmp_path / "c.ply", -6, 6, -6, 6, 5.0)
    edge = _cloud(tmp_path / "edge.ply", 90, 106, -6, 6, 5.0)
    base = {"--cloud": cloud, "--pattern": tmp_path / "sq.svg", "--at": ("0", "0"),
            "--depth": "0.2", "--workpiece": "blank-stainless", "-o": tmp_path / "rep"}
    if args[0] == "--at":
        base["--cloud"] = edge
    base[args[0]] = args[1:] if len(args) > 2 else args[1]
    argv = ["engrave"]
    for k, v in base.items():
        argv += [k, *(v if isinstance(v, tuple) else (v,))]
    res = runner.invoke(app, [str(a) for a in argv])
    assert res.exit_code != 0
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and message in " ".join(res.output.split()), res.output
    assert not (tmp_path / "rep").exists()


PAPER = {"format": "insitu-materials/1", "laser": {"power_w": 20, "spot_um": 50},
         "materials": [{"name": "paper", "threshold_j_cm2": 0.1, "penetration_um": 5,
                        "pen": {"name": "engrave-paper", "power_pct": 5}}]}


def test_the_rig_files_materials_file_is_the_default_table(tmp_path):
    """Without --materials the table is the one the rig file names (options.projection.
    materials_file, relative to the rig file), said in one line; the built-in one else."""
    from insitu.cli.engrave import _materials
    from insitu.formats.json_file import load_json_model
    from insitu.formats.rig import RigConfig

    (tmp_path / "paper.json").write_text(json.dumps(PAPER))
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps({"options": {"projection": {"materials_file": "paper.json"}}}))
    table, said = _materials(None, load_json_model(rig, RigConfig), "paper")
    assert [m.name for m in table.materials] == ["paper"]
    assert said == f"{tmp_path / 'paper.json'} (the rig file's options.projection.materials_file)"
    table, said = _materials(None, RigConfig(), "beech")
    assert said == "the built-in table" and len(table.materials) == 3
    # through the command: stainless steel is not in the rig's table, refused naming its file
    (tmp_path / "sq.svg").write_text(SQUARE)
    cloud = _cloud(tmp_path / "c.ply", -6, 6, -6, 6, 5.0)
    res = runner.invoke(app, ["engrave", "--cloud", str(cloud), "--pattern",
                              str(tmp_path / "sq.svg"), "--at", "0", "0", "--depth", "0.2",
                              "--rig", str(rig), "-o", str(tmp_path / "rep")])
    assert res.exit_code != 0
    assert "paper.json" in res.output and "'paper'" in res.output, res.output
    assert not (tmp_path / "rep").exists()


def test_the_summary_names_the_finishing_rounds_and_their_pen(tmp_path):
    from insitu.cli.common import console
    from insitu.cli.engrave import _summary
    from insitu.formats.materials import DEFAULT_MATERIALS
    from insitu.marking.engrave_plan import finishing_pen
    from insitu.marking.engrave_record import EngraveAsk, EngraveRecord, RoundRecord
    from insitu.services.engrave import EngraveOutcome

    pen, speed = finishing_pen(DEFAULT_MATERIALS.material("stainless-steel"),
                               DEFAULT_MATERIALS.laser)
    rounds = [RoundRecord(job=f"round-0{k}.json", layers=2, paths=9, passes=[[1]],
                          state="marked", finishing=fine,
                          finish=[[1]] if fine else None, finish_speed=speed,
                          finish_pen=pen.model_dump(mode="json") if fine else None)
              for k, fine in ((1, False), (2, True), (3, True))]
    ask = EngraveAsk(pattern="sq.svg", at_mm=(0, 0), depth_mm=0.2, rescan_every=10,
                     material="stainless-steel")
    rec = EngraveRecord(state="done", request=ask, material={}, nominal_rate_mm=0.01,
                        cells={}, history={}, rounds=rounds)
    with console.capture() as out:
        _summary(EngraveOutcome(rec, None), tmp_path)
    text = " ".join(out.get().split())
    assert ("finishing passes in rounds 2, 3: engrave-steel-finish, 80 %, 40 kHz, 1600 mm/s"
            in text)
