"""Scanning use cases: replay a recorded scan, or drive the rig; both stream frames through the
same reconstruction."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from insitu.devices.protocols import Camera, ScanHead
from insitu.devices.sim import SimCamera, SimScanHead, SimWorld
from insitu.errors import ConfigError, DeviceError, InsituError, MeasurementError
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.formats.sequence import Sequence
from insitu.geometry.camera import CameraModel
from insitu.measure.scan import ScanReconstructor
from insitu.rig.files import HeightCalibration
from insitu.services.common import Progress, camera_model
from insitu.services.height import centre_settings, check_same_camera, height_model
from insitu.sim.record import default_region, scan_lines
from insitu.sim.rig import ScanHeadNominal, SimRig, default_rig
from insitu.sim.workpieces import load_mesh_workpiece, make_workpiece



@dataclass(frozen=True)
class ScanSummary:
    points: int
    frames: int
    frames_with_line: int
    method: str
    seconds: float
    bounds_min: tuple[float, float, float]
    bounds_max: tuple[float, float, float]
    outliers_removed: int = 0

    @property
    def coverage(self) -> float:
        """Fraction of frames whose line gave points."""
        return self.frames_with_line / max(self.frames, 1)


@dataclass(frozen=True)
class ScanResult:
    cloud: PointCloud
    summary: ScanSummary


@dataclass(frozen=True)
class ScanFrame:
    """One frame as the scan streams it, for live display: ``index``, the camera ``image``
    (H, W), the line ``centres`` (M, 2) px (u, v) and the ``points`` (K, 3) mm, world frame,
    it gave (before outlier removal)."""

    index: int
    total: int
    image: np.ndarray
    centres: np.ndarray
    points: np.ndarray


FrameCallback = Callable[[ScanFrame], None]


class Cancelled(InsituError):
    """The operator cancelled. ``partial``: for a scan, the result of the lines measured
    before (None when none gave points, or for other work)."""

    def __init__(self, message: str, partial: ScanResult | None = None):
        super().__init__(message)
        self.partial = partial


class ScanInterrupted(DeviceError):
    """A device failed mid-scan; the laser is off. ``partial``: the result of the lines
    measured before the fault (None when none gave points)."""

    def __init__(self, message: str, partial: ScanResult | None):
        super().__init__(message)
        self.partial = partial


def _partial(rec: ScanReconstructor, t0: float) -> ScanResult | None:
    try:
        return _finish(rec, t0)
    except MeasurementError:
        return None


def _finish(rec: ScanReconstructor, t0: float) -> ScanResult:
    cloud = rec.cloud()
    lo, hi = cloud.points.min(axis=0), cloud.points.max(axis=0)
    return ScanResult(cloud, ScanSummary(len(cloud), rec.frames, rec.frames_with_line, rec.method,
                                         time.perf_counter() - t0, tuple(lo), tuple(hi),
                                         rec.outliers_removed))


def reconstructor(camera: CameraModel, pivot_height_mm: float, telecentric: bool,
                  z_range_mm: tuple[float, float], height_cal: HeightCalibration | None,
                  model: str | None, where: str) -> ScanReconstructor:
    """Method 1 without a height calibration, else Method 2 with it (``model``: "sheet",
    "paper" or None for the calibration's default). The line is searched where the focus
    range ``z_range_mm`` can put it."""
    if height_cal is None:
        return ScanReconstructor(camera, pivot_height_mm, telecentric, z_range_mm=z_range_mm)
    check_same_camera(height_cal, camera.width, camera.height, where)
    cal_camera, hmodel = height_model(height_cal, model)
    return ScanReconstructor(cal_camera, pivot_height_mm, telecentric, hmodel,
                             centre_settings(height_cal), z_range_mm)


def scan_replay(folder: str | Path, height_cal: HeightCalibration | None = None,
                model: str | None = None, progress: Progress | None = None,
                cancel: threading.Event | None = None,
                on_frame: FrameCallback | None = None) -> ScanResult:
    """Reconstruct a recorded scan sequence (formats.md §1): Method 1, or Method 2 when a
    height calibration is given. ``on_frame`` sees every frame as it is reconstructed."""
    t0 = time.perf_counter()
    seq = Sequence.open(folder)
    if seq.kind != "scan":
        raise MeasurementError(f"{seq.folder}: a '{seq.kind}' sequence, not a scan")
    head = seq.scan_head
    rec = reconstructor(camera_model(seq.camera), head.pivot_height_mm,
                        head.lens == "telecentric", tuple(head.z_range_mm), height_cal, model,
                        str(seq.folder))
    for i, frame, image in seq:
        if cancel is not None and cancel.is_set():
            raise Cancelled(f"scan cancelled after {i} of {len(seq)} frames", _partial(rec, t0))
        rec.add(i, image, frame.line.start, frame.line.end)
        if on_frame:
            on_frame(ScanFrame(i, len(seq), image, rec.last_centres, rec.last_points))
        if progress:
            progress(i + 1, len(seq))
    return _finish(rec, t0)


def sim_world(workpiece: str = "step-block", seed: int = 0, binning: int = 1,
              rig: SimRig | None = None) -> SimWorld:
    """The simulated station with ``workpiece`` (a catalogue name or a mesh file) on the table."""
    part = (load_mesh_workpiece(workpiece) if Path(workpiece).suffix.lower() in
            (".stl", ".ply", ".obj") else make_workpiece(workpiece))
    return SimWorld(rig or default_rig(seed=seed, binning=binning), parts=[part], seed=seed)


def sim_world_from_rig_file(path: str | Path, workpiece: str = "step-block",
                            binning: int = 1, allow_real: bool = False) -> SimWorld:
    """The simulated station a rig file describes, measuring with the calibration files it
    names (the simulator's truth stays; only the operator's knowledge comes from the files).
    A rig with real devices is refused unless ``allow_real`` (the caller then opens them with
    :func:`insitu.devices.backends.open_station`); the world carries just the operator's
    knowledge, so a real camera or head needs its calibration file."""
    from insitu.rig.files import CameraCalibration, RigConfig, ScanHeadConfig, load_json_model

    cfg = load_json_model(path, RigConfig)
    real = [(k, v) for k, v in (("camera", cfg.camera), ("scan_head", cfg.scan_head),
                                ("stage", cfg.stage)) if v not in ("sim", "none", "replay")]
    if real and not allow_real:
        raise ConfigError(f"{path}: {real[0][0]}: the '{real[0][1]}' backend drives a real "
                          "device; this command runs on the simulated rig only")
    for device, backend, calib, name in (
            ("camera", cfg.camera, cfg.camera_calibration, "camera_calibration"),
            ("scan_head", cfg.scan_head, cfg.scan_head_config, "scan_head_config")):
        if backend not in ("sim", "replay") and not calib:
            raise ConfigError(f"{path}: {name}: required with a real {device} ('{backend}'): "
                              "the measurement needs its calibration")
    world = sim_world(workpiece, seed=cfg.sim_seed, binning=binning)
    rig = world.rig
    if cfg.camera_calibration:
        model = camera_model(
            load_json_model(cfg.resolve(cfg.camera_calibration), CameraCalibration).camera)
        size, sim_size = (model.width, model.height), (rig.camera.width, rig.camera.height)
        if cfg.camera in ("sim", "replay") and size != sim_size:
            raise ConfigError(f"{cfg.camera_calibration}: camera is {model.width}×{model.height} "
                              f"px, the rig's is {rig.camera.width}×{rig.camera.height} px")
        rig = replace(rig, operator_camera=model)
    if cfg.scan_head_config:
        head = load_json_model(cfg.resolve(cfg.scan_head_config), ScanHeadConfig)
        rig = replace(rig, nominal=ScanHeadNominal(
            head.lens, head.pivot_height_mm, head.mirror_distance_mm, head.mirror_separation_mm,
            tuple(head.field_size_mm), tuple(head.z_range_mm)))
    world.rig = rig
    return world


def scan_live(world: SimWorld, spacing: float = 0.5, region=None,
              height_cal: HeightCalibration | None = None, model: str | None = None,
              progress: Progress | None = None, cancel: threading.Event | None = None,
              on_frame: FrameCallback | None = None, exposure_ms: float | None = None,
              camera: Camera | None = None, head: ScanHead | None = None,
              speed_mm_s: float | None = None) -> ScanResult:
    """Drive the rig: step the line over ``region`` (x0, x1, y0, y1) mm and reconstruct each
    frame as it arrives (``on_frame`` sees each; ``exposure_ms``: the camera's, default its
    own; ``speed_mm_s``: the head's line sweep speed, default its own). ``camera``, ``head``: real devices (default: the world's simulated ones). The laser
    is off when this returns or raises; a device fault raises :class:`ScanInterrupted` with
    what was measured before it."""
    t0 = time.perf_counter()
    region = tuple(region) if region is not None else default_region(world)
    _check_region(region, world)
    lines = scan_lines(region, spacing)
    rig = world.rig
    rec = reconstructor(rig.operator_camera, rig.nominal.pivot_height_mm,
                        rig.nominal.lens == "telecentric", rig.nominal.z_range_mm, height_cal,
                        model, "live scan")
    camera = camera if camera is not None else SimCamera(world)
    head = head if head is not None else SimScanHead(world)
    if exposure_ms is not None:
        camera.set_exposure(exposure_ms)
    if speed_mm_s is not None:
        head.set_line_speed(speed_mm_s)
    try:
        for i, (a, b) in enumerate(lines):
            if cancel is not None and cancel.is_set():
                raise Cancelled(f"scan cancelled after {i} of {len(lines)} lines",
                                _partial(rec, t0))
            try:
                head.show_line(a, b)
                image = camera.grab()
            except DeviceError as e:
                head.off()
                raise ScanInterrupted(f"scan stopped at line {i + 1} of {len(lines)}, laser "
                                      f"off: {e}", _partial(rec, t0)) from e
            rec.add(i, image, a, b)
            if on_frame:
                on_frame(ScanFrame(i, len(lines), image, rec.last_centres, rec.last_points))
            if progress:
                progress(i + 1, len(lines))
    finally:
        head.off()
    return _finish(rec, t0)


def _check_region(region, world: SimWorld) -> None:
    x0, x1, y0, y1 = region
    half = np.asarray(world.rig.nominal.field_size_mm) / 2
    if not (x0 < x1 and y0 < y1):
        raise MeasurementError(f"--region {x0:g} {x1:g} {y0:g} {y1:g}: expected X0 < X1 and Y0 < Y1")
    if max(abs(x0), abs(x1)) > half[0] or max(abs(y0), abs(y1)) > half[1]:
        raise MeasurementError(f"--region {x0:g} {x1:g} {y0:g} {y1:g}: outside the scan field "
                               f"±{half[0]:g} × ±{half[1]:g} mm")


def save_cloud(result: ScanResult, path: str | Path) -> None:
    if len(result.cloud) == 0:
        raise MeasurementError("the scan gave no points; nothing written")
    write_ply(path, result.cloud)
