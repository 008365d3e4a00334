"""GenICam backend through harvesters and a real GenTL producer: the Viky simulator shipped in
the `genicam` wheel (three virtual cameras, 400 × 400, Mono8 or RGBa8, free-running, no
exposure, gain or trigger features: those paths are checked for their clear refusal)."""

import time
from pathlib import Path

import genicam
import numpy as np
import pytest

from fakes.station import allow
from insitu.devices.camera_genicam import GenICamCamera
from insitu.devices.protocols import Camera
from insitu.errors import ConfigError, DeviceError

VIKY = Path(genicam.__file__).with_name("viky.cti")
pytestmark = pytest.mark.skipif(not VIKY.is_file(), reason="genicam wheel without viky.cti")


@pytest.fixture(scope="module", autouse=True)
def allowed():
    allow(VIKY)                                     # the station allows the producer


@pytest.fixture
def cam():
    c = GenICamCamera(VIKY, serial="1", timeout_s=3.0)
    yield c
    c.close()


def test_opens_by_serial_and_grabs_mono8(cam):
    assert isinstance(cam, Camera)
    assert (cam.width, cam.height) == (400, 400)
    assert cam.nodes.PixelFormat.value == "Mono8"
    assert cam.ia.data_streams[0].node_map.StreamBufferHandlingMode.value == "NewestOnly"
    frames = [cam.grab() for _ in range(3)]
    assert all(f.shape == (400, 400) and f.dtype == np.uint8 for f in frames)
    assert frames[0].std() > 0                      # a picture, not an empty buffer


def test_free_running_grab_returns_a_frame_exposed_after_the_call(cam):
    cam.nodes.AcquisitionFrameRate.value = 5.0      # 200 ms per frame
    cam.grab()
    time.sleep(0.7)                                 # buffers fill meanwhile
    t0 = time.monotonic()
    cam.grab()
    assert time.monotonic() - t0 > 0.05             # it waited for a new frame


def test_timeout_is_a_device_error(cam):
    cam.nodes.AcquisitionFrameRate.value = 1.0
    cam.grab()
    with pytest.raises(DeviceError, match="no frame within 0.05 s"):
        cam.grab(timeout_s=0.05)


def test_missing_features_and_formats_are_refused_clearly(cam):
    with pytest.raises(DeviceError, match="has no feature ExposureTime"):
        cam.set_exposure(2.0)
    with pytest.raises(DeviceError, match="has no feature Gain"):
        cam.set_gain(3.0)
    cam.close()
    with pytest.raises(DeviceError, match="PixelFormat Mono12 is not offered .*RGBa8, Mono8"):
        GenICamCamera(VIKY, serial="2", pixel_format="Mono12")
    with pytest.raises(DeviceError, match="has no feature TriggerSelector"):
        GenICamCamera(VIKY, serial="2", trigger="software")


def test_bad_configuration(tmp_path):
    with pytest.raises(DeviceError, match="producer .*nope.cti not found"):
        GenICamCamera(tmp_path / "nope.cti")
    with pytest.raises(DeviceError, match=r"no camera with serial 7 \(found: 0, 1, 2\)"):
        GenICamCamera(VIKY, serial="7")
    with pytest.raises(ConfigError, match="pixel_format"):
        GenICamCamera(VIKY, pixel_format="RGB8")
    with pytest.raises(ConfigError, match="trigger"):
        GenICamCamera(VIKY, trigger="sometimes")
