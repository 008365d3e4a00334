"""What the operator is told: scripts/setup.sh says what it installs and that pip takes a
while (run against stand-ins for dpkg-query, apt-get, sudo and the virtual environment's pip;
silent when all is there); `insitu galvo correct --help` and the operator guide say how to
write targets.csv."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tool(folder: Path, name: str, body: str) -> None:
    path = folder / name
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(0o755)


def _setup(tmp_path: Path, missing: str) -> str:
    fake = tmp_path / "bin"
    fake.mkdir(exist_ok=True)
    _tool(fake, "dpkg-query", f'case "$*" in *" {missing}") echo "unknown";; '
                              '*) echo "install ok installed";; esac')
    _tool(fake, "apt-get", f'echo "apt-get $*" >> {tmp_path}/calls')
    _tool(fake, "sudo", 'exec "$@"')
    venv = tmp_path / "venv" / "bin"
    venv.mkdir(parents=True, exist_ok=True)
    _tool(venv, "python", f'[ "$1 $2" = "-m pip" ] && {{ echo "pip $*" >> {tmp_path}/calls; '
                          f'exit 0; }}\nexec {sys.executable} "$@"')
    env = {**os.environ, "PATH": f"{fake}:{os.environ['PATH']}",
           "INSITU_VENV": str(tmp_path / "venv")}
    env.pop("INSITU_EXTRAS", None)
    res = subprocess.run(["bash", "-c", f"source {ROOT}/scripts/setup.sh"], env=env,
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr
    return res.stdout + res.stderr


def test_setup_says_what_it_installs_and_is_silent_when_done(tmp_path):
    out = _setup(tmp_path, "xauth")
    assert "installing 1 system packages with apt-get" in out and "xauth" in out
    assert "installing insitu[gui,test,test-gui] into" in out and "minute or two" in out
    for name in ("numpy", "open3d", "matplotlib", "PySide6-Essentials", "pytest-qt"):
        assert name in out, out
    calls = (tmp_path / "calls").read_text()
    assert "apt-get install" in calls and "xauth" in calls and "pip install -e" in calls
    assert _setup(tmp_path, "nothing-missing") == ""             # everything there: quiet


def test_the_targets_csv_of_galvo_correct_is_explained(monkeypatch):
    from typer.testing import CliRunner

    from insitu.cli.main import app

    monkeypatch.setenv("COLUMNS", "200")
    res = CliRunner().invoke(app, ["galvo", "correct", "--help"])
    text = " ".join(res.output.replace("│", " ").split())
    for words in ("the header x,y, then one target per line", "x and y in mm",
                  "focal plane z = 0", "origin at the field centre", "-40.5,12.25"):
        assert words in text, text
    guide = " ".join((ROOT / "docs" / "operator-guide.md").read_text().split())
    assert "targets.csv" in guide and "one target per line" in guide
