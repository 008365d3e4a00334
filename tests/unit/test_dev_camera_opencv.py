"""OpenCV camera backend at VideoCapture's own boundary: image sequences, a video file and a
FIFO that never delivers (as a camera that hangs)."""

import os

import cv2
import numpy as np
import pytest

from insitu.devices.camera_opencv import OpenCVCamera
from insitu.devices.protocols import Camera
from insitu.errors import DeviceError


def write_sequence(folder, n=4, dtype=np.uint8, colour=True):
    for i in range(n):
        img = np.zeros((48, 64), dtype)
        img[10 + i, :] = 200 if dtype == np.uint8 else 40000      # a line that moves down
        if colour:
            img = np.dstack([img, img, img])
        cv2.imwrite(str(folder / f"frame_{i:04d}.png"), img)
    return str(folder / "frame_%04d.png")


def test_image_sequence_frames_in_order_then_a_clear_end(tmp_path):
    cam = OpenCVCamera(write_sequence(tmp_path), timeout_s=2.0)
    assert isinstance(cam, Camera)
    assert (cam.width, cam.height) == (64, 48)
    for i in range(4):
        f = cam.grab()
        assert f.shape == (48, 64) and f.dtype == np.uint8
        assert int(np.argmax(f[:, 5])) == 10 + i and f.max() == 200
    with pytest.raises(DeviceError, match="gave no frame"):
        cam.grab()
    cam.close()


def test_sixteen_bit_sequence_stays_sixteen_bit(tmp_path):
    cam = OpenCVCamera(write_sequence(tmp_path, 2, np.uint16, colour=False))
    f = cam.grab()
    assert f.dtype == np.uint16 and f.max() == 40000 and int(np.argmax(f[:, 0])) == 10
    cam.close()


def test_video_file(tmp_path):
    path = tmp_path / "scan.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    for i in range(5):
        img = np.zeros((48, 64, 3), np.uint8)
        img[:, 20 + 4 * i] = 255
        w.write(img)
    w.release()
    cam = OpenCVCamera(str(path))
    cols = [int(np.argmax(cam.grab()[24])) for _ in range(5)]
    assert cols == [20, 24, 28, 32, 36]
    cam.close()


def test_controls_the_source_lacks_are_refused_clearly(tmp_path):
    seq = write_sequence(tmp_path, 1)
    with pytest.raises(DeviceError, match="does not support setting the width"):
        OpenCVCamera(seq, resolution=(640, 480))
    cam = OpenCVCamera(seq)
    with pytest.raises(DeviceError, match="does not support setting the exposure"):
        cam.set_exposure(5.0)
    with pytest.raises(DeviceError, match="exposure must be > 0 ms"):
        cam.set_exposure(0.0)
    with pytest.raises(DeviceError, match="does not support setting the gain"):
        cam.set_gain(2.0)
    cam.close()


def test_missing_source_cannot_be_opened(tmp_path):
    with pytest.raises(DeviceError, match="cannot open it"):
        OpenCVCamera(str(tmp_path / "nothing_%04d.png"))


def test_camera_that_never_answers_times_out(tmp_path):
    fifo = tmp_path / "camera.mjpeg"
    os.mkfifo(fifo)
    try:
        with pytest.raises(DeviceError, match=r"open: no answer within 0.3 s"):
            OpenCVCamera(str(fifo), timeout_s=0.3)
    finally:
        os.close(os.open(fifo, os.O_WRONLY))       # release the stuck reader thread
