"""The integration tier: whole runs on the simulated rig (scans, production, marking and its
kills and faults, calibrations from simulated recordings) and on the independent recordings.
Its station file is its own, empty until a test allows a library.

The recordings several tests read are made once per run (``shared`` in tests/conftest.py: one
copy for all of pytest-xdist's workers), each fixture returning its folder; tests copy what they
damage."""

from pathlib import Path

import pytest

from fakes.station import isolated_station
from run_folders import shared

# another renderer's recordings, beside the repository (their truth.json only scores)
RECORDINGS = Path(__file__).resolve().parents[3] / "shared" / "recordings"


@pytest.fixture(scope="session", autouse=True)
def station_file(tmp_path_factory):
    yield from isolated_station(tmp_path_factory)


@pytest.fixture(scope="session")
def independent_height_cal_file(tmp_path_factory) -> Path:
    """The independent recordings' height calibration (their coarse plate) fitted once."""
    from insitu.formats.json_file import save_json_model
    from insitu.services import calibrate_height

    hcal = RECORDINGS / "height-calibration-coarse-independent"
    assert hcal.is_dir(), f"{RECORDINGS}: the shared recordings are missing"

    def fit(folder):
        save_json_model(folder / "height.json", calibrate_height(hcal))
    return shared(tmp_path_factory, "independent-height-cal", fit) / "height.json"


@pytest.fixture(scope="session")
def independent_scan(independent_height_cal_file):
    """The independent recording of the step block (step-block-independent) replayed with
    Method 2 and its own plate's calibration: (its folder, the ``ScanResult``)."""
    from insitu.services import load_height_calibration, scan_replay

    folder = RECORDINGS / "step-block-independent"
    assert folder.is_dir(), f"{RECORDINGS}: the shared recordings are missing"
    return folder, scan_replay(folder, load_height_calibration(independent_height_cal_file))


@pytest.fixture(scope="session")
def crossed_height_cal(tmp_path_factory) -> Path:
    """A height calibration recorded with crossed lines at binning 4 on the step block's
    station (6 heights −10 … 15 mm, 7 offsets −30 … 30 mm along y and the crossed lines over
    the same rectangle; ``hcal``), fitted and saved (``height.json``): their folder."""
    from insitu.formats.json_file import save_json_model
    from insitu.services import calibrate_height
    from insitu.services.record import record_height_calibration
    from insitu.services.station import connect

    def record(folder):
        with connect(None, "step-block", 0, 4) as station:
                record_height_calibration(station, folder / "hcal",
                                      (-10.0, -5.0, 0.0, 5.0, 10.0, 15.0),
                                      tuple(float(x) for x in range(-30, 31, 10)))
        save_json_model(folder / "height.json", calibrate_height(folder / "hcal"))
    return shared(tmp_path_factory, "crossed-height-cal", record)


@pytest.fixture(scope="session")
def scan_recording(tmp_path_factory) -> Path:
    """``insitu sim record scan`` of the step block, binning 4, lines 2 mm apart."""
    from typer.testing import CliRunner

    from insitu.cli.main import app

    def record(folder):
        res = CliRunner().invoke(app, ["sim", "record", "scan", "--workpiece", "step-block",
                                       "-o", str(folder / "scan"), "--binning", "4",
                                       "--spacing", "2.0"])
        assert res.exit_code == 0, res.output
    return shared(tmp_path_factory, "scan-step-block", record) / "scan"


@pytest.fixture(scope="session")
def camera_recording(tmp_path_factory) -> Path:
    """A camera calibration recorded by ``insitu sim record camera-calibration`` on the
    simulated rig of seed 2 at binning 2: the board in 4 views, the scan head's axis lines
    (recorded by default), the board's truth."""
    from typer.testing import CliRunner

    from insitu.cli.main import app

    def record(folder):
        res = CliRunner().invoke(app, ["sim", "record", "camera-calibration", "-o",
                                       str(folder / "camcal"), "--views", "4", "--binning", "2",
                                       "--seed", "2"])
        assert res.exit_code == 0, res.output
    return shared(tmp_path_factory, "camera-calibration", record) / "camcal"


@pytest.fixture(scope="session")
def field_recording(tmp_path_factory) -> Path:
    """Field calibration spots, 7 × 7, on the rig of seed 3 at binning 4 (a few of them
    outside the camera's view)."""
    from insitu.services.record import record_field_calibration
    from insitu.services.station import simulated
    from insitu.sim.rig import default_rig
    from insitu.sim.world import SimWorld

    def record(folder):
        record_field_calibration(simulated(SimWorld(default_rig(3, binning=4), seed=3)),
                                 folder / "rec", n=7)
    return shared(tmp_path_factory, "field-spots", record) / "rec"


@pytest.fixture(scope="session")
def marked_field_recording(tmp_path_factory) -> Path:
    """Circles of 2 mm marked uncorrected on a 9 × 9 grid over ±80 mm, imaged (rig of seed 3,
    binning 2)."""
    from insitu.services.record import record_marked_field_calibration
    from insitu.services.station import simulated
    from insitu.sim.rig import default_rig
    from insitu.sim.world import SimWorld

    def record(folder):
        record_marked_field_calibration(simulated(SimWorld(default_rig(3, binning=2), seed=3)),
                                        folder / "rec", n=9, half_mm=80.0)
    return shared(tmp_path_factory, "field-marked", record) / "rec"


@pytest.fixture(scope="session")
def step_block_reference(tmp_path_factory) -> Path:
    """A first scan of the step block where it lay (binning 2, lines 0.5 mm apart: what
    locating needs), as a PLY."""
    from insitu.formats.pointcloud import write_ply
    from insitu.services.scan import scan_live
    from insitu.services.station import connect

    def scan(folder):
        with connect(None, "step-block", 0, 2) as station:
            write_ply(folder / "ref.ply", scan_live(station, 0.5).cloud)
    return shared(tmp_path_factory, "step-block-reference", scan) / "ref.ply"
