"""Shared by every tier (unit, integration, gui, hardware): the simulated boards import as
``fakes`` (``tests/fakes``), the recordings are in ``tests/data``; under ``CliRunner`` a command
that lets an exception escape (anything but its exit) fails the test, whatever else it checks.

``INSITU_TEST_NO_QT=1`` (the core tier of ``scripts/test.sh``, with ``-p no:pytest-qt``): the
GUI packages cannot be imported, as where insitu is installed without its ``gui`` extra. The
fuzz seed (``INSITU_FUZZ_SEED``, drawn when unset) is fixed for the run and printed in its
header. The height calibration of ``tests/data/height-cal-b4`` is fitted once per run
(``height_cal_file``, a :func:`run_folders.shared` folder)."""

import os
import random
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parent))
from run_folders import shared  # noqa: E402

DATA = Path(__file__).parent / "data"

GUI_PACKAGES = ("PySide6", "shiboken6", "OpenGL", "pytestqt")
if os.environ.get("INSITU_TEST_NO_QT") == "1":
    loaded = [name for name in GUI_PACKAGES if sys.modules.get(name) is not None]
    if loaded:
        raise pytest.UsageError(f"INSITU_TEST_NO_QT=1: {', '.join(loaded)} already imported "
                                "(run pytest with -p no:pytest-qt)")
    for name in GUI_PACKAGES:
        sys.modules[name] = None                 # import raises ModuleNotFoundError

os.environ.setdefault("INSITU_FUZZ_SEED", str(random.SystemRandom().randrange(10**9)))


def pytest_report_header(config):
    seed = os.environ["INSITU_FUZZ_SEED"]
    qt = "blocked" if os.environ.get("INSITU_TEST_NO_QT") == "1" else "importable"
    return f"insitu: fuzz seed {seed} (INSITU_FUZZ_SEED={seed} repeats this run); Qt {qt}"


@pytest.fixture(autouse=True)
def _commands_let_no_exception_escape(monkeypatch):
    invoke = CliRunner.invoke

    def checked(self, *args, **kwargs):
        res = invoke(self, *args, **kwargs)
        if res.exception is not None and not isinstance(res.exception, SystemExit):
            raise AssertionError(f"the command raised {type(res.exception).__name__}: "
                                 f"{res.exception}") from res.exception
        return res
    monkeypatch.setattr(CliRunner, "invoke", checked)


@pytest.fixture(scope="session")
def height_cal_file(tmp_path_factory) -> Path:
    """tests/data/height-cal-b4 (91 frames, binning 4) fitted by ``insitu calibrate height``:
    the JSON file it writes, its residual grid's picture beside it (.png)."""
    from insitu.cli.main import app

    def fit(folder):
        res = CliRunner().invoke(app, ["calibrate", "height", str(DATA / "height-cal-b4"),
                                       "-o", str(folder / "height.json")])
        assert res.exit_code == 0, res.output
    return shared(tmp_path_factory, "height-cal-b4", fit) / "height.json"


@pytest.fixture(scope="session")
def height_cal(height_cal_file):
    """The fitted height calibration of tests/data/height-cal-b4 (``HeightCalibration``)."""
    from insitu.services import load_height_calibration

    return load_height_calibration(height_cal_file)
