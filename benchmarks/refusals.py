"""Issue 16's list of implausible inputs: each must be refused with one line naming it, exit 1,
within a second, nothing written. For every case: the time from the command's start to its
refusal (in process, the package already imported), the exit code, the line, whether a file
appeared; then the wall time of one whole ``insitu`` process (import included) for comparison.

Run: .venv/bin/python benchmarks/refusals.py
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table
from typer.testing import CliRunner

from insitu.cli.main import app

console = Console(markup=False, emoji=False, width=160)
DATA = Path(__file__).parents[1] / "tests" / "data"


def _files(d: Path) -> dict[str, Path]:
    """The simulated rig's files, each broken one way in a copy; a job and a height
    calibration out of bounds."""
    assert CliRunner().invoke(app, ["sim", "calib", "-o", str(d)]).exit_code == 0
    rig = json.loads((d / "rig.json").read_text())

    def edited(src, dst, edit):
        data = json.loads((d / src).read_text())
        edit(data)
        (d / dst).write_text(json.dumps(data))
        return dst

    rigs = {"pivot 1e-300": {"scan_head_config": edited(
                "scan-head.json", "h1.json", lambda h: h.update(pivot_height_mm=1e-300))},
            "mirror_separation 1e300": {"scan_head_config": edited(
                "scan-head.json", "h2.json", lambda h: h.update(mirror_separation_mm=1e300))},
            "distortion k1 1e300": {"camera_calibration": edited(
                "camera.json", "c1.json", lambda c: c["camera"]["dist"].__setitem__(0, 1e300))},
            "LMC bits_per_deg 0": {"scan_head": "lmc", "options": {"lmc": {"bits_per_deg": 0}}},
            "LMC bits_per_deg < 0": {"scan_head": "lmc",
                                     "options": {"lmc": {"bits_per_deg": -1500}}}}
    out = {}
    for i, (name, change) in enumerate(rigs.items()):
        (d / f"rig{i}.json").write_text(json.dumps({**rig, **change}))
        out[name] = d / f"rig{i}.json"
    for name, speed in (("speed 1e-300", 1e-300), ("speed 1e308", 1e308)):
        p = d / f"job-{speed:g}.json"
        p.write_text(json.dumps({"laser": {"mark_speed_mm_s": speed},
                                 "paths": [{"points": [[0, 0, 0], [1, 0, 0]]}]}))
        out[name] = p
    seq = json.loads((DATA / "height-cal-b2.json").read_text())
    seq["sheet"]["exponents"][1] = [-1, 0, 0]
    (d / "hcal.json").write_text(json.dumps(seq))
    out["negative exponent"] = d / "hcal.json"
    return out


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        f, o = _files(d / "files"), d / "out"
        o.mkdir()
        mark = ["mark", "--cloud", str(d / "c.ply"), "--pattern", "qr:x", "--at", "0", "0",
                "-o", str(o / "j.json")]
        cases = {
            "--binning 0": ["scan", "-o", str(o / "c.ply"), "--binning", "0"],
            "--spacing nan": ["scan", "-o", str(o / "c.ply"), "--spacing", "nan"],
            "--rotate inf": [*mark, "--rotate", "inf"],
            "--seed -1": ["scan", "-o", str(o / "c.ply"), "--seed", "-1"],
            "--speed 1e-300": [*mark, "--speed", "1e-300"],
            "--speed 1e308": [*mark, "--speed", "1e308"],
            **{f"job {k}": ["job", "show", str(f[k])] for k in ("speed 1e-300", "speed 1e308")},
            **{k: ["scan", "--rig", str(f[k]), "-o", str(o / "c.ply")]
               for k in ("pivot 1e-300", "mirror_separation 1e300", "distortion k1 1e300",
                         "LMC bits_per_deg 0", "LMC bits_per_deg < 0")},
            "negative exponent": ["scan", "--replay", str(DATA / "scan-step-block-b2"),
                                  "--height-cal", str(f["negative exponent"]),
                                  "-o", str(o / "c.ply")],
            "file a[/]b.json": ["job", "show", str(d / "a[" / "]b.json")],
        }
        table = Table(title="refusals (in process)", show_lines=False)
        for col in ("input", "ms", "exit", "lines", "written", "the line"):
            table.add_column(col)
        runner, worst = CliRunner(), 0.0
        for name, args in cases.items():
            t0 = time.perf_counter()
            res = runner.invoke(app, args)
            ms = 1000 * (time.perf_counter() - t0)
            worst = max(worst, ms)
            lines = res.output.strip().splitlines()
            table.add_row(name, f"{ms:.0f}", str(res.exit_code), str(len(lines)),
                          str(len(list(o.iterdir()))), lines[0] if lines else "")
        console.print(table)
        console.print(f"slowest refusal: {worst:.0f} ms")
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "from insitu.cli.main import main; main()",
                        *cases["--binning 0"]], capture_output=True)
        console.print(f"one whole process (--binning 0, import included): "
                      f"{time.perf_counter() - t0:.2f} s")


if __name__ == "__main__":
    main()
