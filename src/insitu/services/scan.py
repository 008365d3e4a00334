"""Scanning use cases: replay a recorded scan, or drive the station; one loop streams the
frames of both through the same reconstruction."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from insitu.devices.clock import StepTimer
from insitu.devices.protocols import Camera, ScanHead, pixel_bits_of
from insitu.devices.replay import ReplayCamera
from insitu.errors import DeviceError, InsituError, MeasurementError
from insitu.formats.calibration import HeightCalibration
from insitu.formats.pointcloud import PointCloud, write_ply
from insitu.formats.rig_record import RigRecord
from insitu.formats.sequence import Sequence
from insitu.geometry.camera import CameraModel
from insitu.reconstruct.bands import Packing
from insitu.reconstruct.packing import FramePlan, RecordedPlan
from insitu.reconstruct.plan import check_region, clip_lines, scan_lines
from insitu.reconstruct.scan import ExcessLight, ScanReconstructor, excess_room_light
from insitu.reconstruct.turned_sheet import CROSS_ANGLE_DEG
from insitu.services.common import Progress, camera_model
from insitu.services.height import centre_settings, check_same_camera, crossed_model, height_model
from insitu.services.room_light import station_room_light
from insitu.services.scan_frames import (
    ScanInterrupted,
    Shots,
    Stream,
    describe_packing,
    laser_off_frames,
    moving_window,
    recorded_excess,
    region_of_interest,
    survey_heights,
)
from insitu.services.station import Station
from insitu.vision.extract import CentreSettings


@dataclass(frozen=True)
class ScanSummary:
    """``frames``: the lines measured (one a frame unless several share an exposure),
    ``frames_with_line``: those that gave points, ``camera_frames``: the frames taken (a
    survey frame's too, the room light's not), ``packing``: how many lines a frame held
    and the heights their bands followed. ``seconds``: the wall clock's; ``station_s``: the
    station's own (its camera frames and head: :mod:`insitu.devices.clock`; None for a
    replay or on a real rig); ``cpu_s``: the computer's processing (the simulator's drawing
    left out)."""

    points: int
    frames: int
    frames_with_line: int
    method: str
    seconds: float
    bounds_min: tuple[float, float, float]
    bounds_max: tuple[float, float, float]
    outliers_removed: int = 0
    unconfirmed_removed: int = 0
    ambient: str = "none"      # "yes": each point has its grey value; else why not
    station_s: float | None = None
    cpu_s: float = 0.0
    camera_frames: int = 0
    packing: str = "one line a frame"

    @property
    def coverage(self) -> float:
        """Fraction of frames whose line gave points."""
        return self.frames_with_line / max(self.frames, 1)


@dataclass(frozen=True)
class ScanResult:
    """The scan's ``cloud``, its ``summary`` and the ``room_light`` frame (H, W) taken (or
    recorded) before the lines, laser off (None: none), whose edges refine a part's pose."""

    cloud: PointCloud
    summary: ScanSummary
    room_light: np.ndarray | None = None


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


def _partial(rec: ScanReconstructor, t0: StepTimer, rig: RigRecord | None,
             ambient: str = "none", frames: int = 0, packing: str = "") -> ScanResult | None:
    try:
        return _finish(rec, t0, rig, ambient, None, frames, packing)
    except MeasurementError:
        return None


def _finish(rec: ScanReconstructor, t0: StepTimer, rig: RigRecord | None = None,
            ambient: str = "none", room_light: np.ndarray | None = None, frames: int = 0,
            packing: str = "one line a frame") -> ScanResult:
    """The result so far, its cloud recording ``rig`` (the station's; None for a replay)."""
    cloud = replace(rec.cloud(), rig=rig)
    if not len(cloud):
        raise MeasurementError(f"no point of the {rec.frames} frames' lines passed the "
                               "outlier tests (too few neighbours: lines too far apart, or "
                               "frames too coarse)")
    lo, hi = cloud.points.min(axis=0), cloud.points.max(axis=0)
    t = t0.elapsed()
    return ScanResult(cloud, ScanSummary(len(cloud), rec.frames, rec.frames_with_line, rec.method,
                                         t.wall, tuple(lo), tuple(hi),
                                         rec.outliers_removed, rec.unconfirmed_removed,
                                         ambient, t.station, t.cpu, frames, packing),
                      room_light)


def reconstructor(camera: CameraModel, pivot_height_mm: float, telecentric: bool,
                  z_range_mm: tuple[float, float], height_cal: HeightCalibration | None,
                  model: str | None, where: str, cross: bool = False,
                  centres: CentreSettings | None = None,
                  pixel_bits: int | None = None) -> ScanReconstructor:
    """Method 1 without a height calibration, else Method 2 with it (``model``: "sheet",
    "paper" or None for the calibration's default; with ``cross`` also its crossed lines'
    model, MeasurementError when it has none). The line is searched where the focus range
    ``z_range_mm`` can put it; its centres found with ``centres`` (None: as the calibration
    was made, else the default); ``pixel_bits``: the frames' significant bits (None: their
    dtype's)."""
    if height_cal is None:
        return ScanReconstructor(camera, pivot_height_mm, telecentric,
                                 settings=centres or CentreSettings(), z_range_mm=z_range_mm,
                                 pixel_bits=pixel_bits)
    check_same_camera(height_cal, camera.width, camera.height, where)
    cal_camera, hmodel = height_model(height_cal, model)
    return ScanReconstructor(cal_camera, pivot_height_mm, telecentric, hmodel,
                             centres or centre_settings(height_cal), z_range_mm,
                             cross_model=crossed_model(height_cal) if cross else None,
                             pixel_bits=pixel_bits)


def cross_angle(height_cal: HeightCalibration | None) -> float:
    """The crossed pass's line angle to x, degrees: the height calibration's crossed lines',
    else (Method 1, or a calibration without them) :data:`CROSS_ANGLE_DEG`."""
    spec = height_cal.sheet_cross if height_cal is not None else None
    return spec.line_angle_deg if spec is not None else CROSS_ANGLE_DEG


def plan_lines(region, spacing: float, cross: bool = False,
               height_cal: HeightCalibration | None = None,
               cross_spacing: float | None = None) -> list:
    """The lines of a scan over ``region``: along y ``spacing`` mm apart, then with ``cross``
    a second, crossed pass over the same region (:func:`cross_angle`), ``cross_spacing`` mm
    apart (None: ``spacing``)."""
    lines = scan_lines(region, spacing)
    if not cross:
        return lines
    return lines + scan_lines(region, cross_spacing or spacing, cross_angle(height_cal))


def scan_replay(folder: str | Path, height_cal: HeightCalibration | None = None,
                model: str | None = None, progress: Progress | None = None,
                cancel: threading.Event | None = None,
                on_frame: FrameCallback | None = None,
                heights: tuple[float, float] | None = None,
                packing: Packing = Packing(),
                centres: CentreSettings | None = None) -> ScanResult:
    """Reconstruct a recorded scan sequence (docs/formats.md, recorded sequence): Method 1,
    or Method 2 when a height calibration is given. The recording is a camera like any other
    (:class:`~insitu.devices.replay.ReplayCamera`): the same loop as a live scan; frames of
    one ``line`` and of several ``lines`` alike (:class:`~insitu.reconstruct.packing.
    RecordedPlan`: the lines of a frame told apart by their bands, for the ``heights`` given,
    else those its survey frame measured). Its ambient frame, when it has one, gives each
    point its ``ambient`` grey value; its laser-off frames of packed exposures are
    subtracted in part from those frames, as a live scan's. ``centres``: how line centres are
    found (None: as the height calibration was made, else the default)."""
    t0 = StepTimer(None)
    seq = Sequence.open(folder)
    if seq.kind != "scan":
        raise MeasurementError(f"{seq.folder}: a '{seq.kind}' sequence, not a scan")
    head = seq.scan_head
    drawn = [f.drawn() for f in seq.frames]
    plan = RecordedPlan(drawn, [f.survey for f in seq.frames], tuple(head.z_range_mm),
                        packing, heights)
    rec = reconstructor(camera_model(seq.camera), head.pivot_height_mm,
                        head.lens == "telecentric", tuple(head.z_range_mm), height_cal, model,
                        str(seq.folder), cross=any(abs(a[0] - b[0]) > 1e-9
                                                   for f in drawn for a, b in f),
                        centres=centres, pixel_bits=seq.pixel_bits)
    return _scan(ReplayCamera(seq), RecordedHead(), plan, rec, t0, "frames", progress, cancel,
                 on_frame, room_light=seq.read_ambient, excess=recorded_excess(seq))


def scan_live(station: Station, spacing: float = 0.5, region=None,
              height_cal: HeightCalibration | None = None, model: str | None = None,
              progress: Progress | None = None, cancel: threading.Event | None = None,
              on_frame: FrameCallback | None = None, exposure_ms: float | None = None,
              speed_mm_s: float | None = None, cross: bool = False,
              cross_spacing: float | None = None, lines_per_frame: int | str | None = None,
              heights: tuple[float, float] | None = None,
              packing: Packing = Packing(),
              centres: CentreSettings | None = None, room_light: bool = True,
              within: np.ndarray | None = None) -> ScanResult:
    """Drive the station: step the line over ``region`` (x0, x1, y0, y1) mm (default: the
    station's, which a real rig does not have), with ``cross`` a second pass of crossed
    lines over it ``cross_spacing`` mm apart (:func:`plan_lines`), and reconstruct each
    frame as it arrives
    (``on_frame`` sees each; ``exposure_ms``: the camera's, default its own, for each line;
    ``speed_mm_s``: the head's line sweep speed, default its own; ``centres``: how line
    centres are found, default as the height calibration was made; ``within``: a convex
    outline (M, 2) mm the lines are clipped to, :func:`~insitu.reconstruct.plan.clip_lines`).
    ``heights`` (low, high) mm, when known: each line is searched only where they put it
    (None: the head's focus range). ``lines_per_frame``: None or 1, K or "auto"
    (:mod:`insitu.reconstruct.packing`: a survey frame bounds the heights, unless
    ``heights`` are known, then the lines are packed by them; a frame of K lines is exposed
    K times as long). First, with ``room_light``, a
    frame with the laser off under the room light, auto-exposed
    (:func:`~insitu.services.room_light.station_room_light`), gives each point its
    ``ambient`` grey value; the camera then reads out only the region the lines can reach
    (a camera that can). The laser is off when this returns or raises; a device fault
    raises :class:`ScanInterrupted` with what was measured before it."""
    t0 = StepTimer(station.clock)
    region = tuple(region) if region is not None else station.default_region()
    rig = station.rig
    check_region(region, rig.head.field_size_mm)
    lines = plan_lines(region, spacing, cross, height_cal, cross_spacing)
    if within is not None:
        lines = clip_lines(lines, within, spacing)
    rec = reconstructor(rig.camera, rig.head.pivot_height_mm, rig.head.lens == "telecentric",
                        heights or rig.head.z_range_mm, height_cal, model, "live scan", cross,
                        centres, pixel_bits_of(station.devices.camera))
    plan = FramePlan(lines, rec.sheets, rig.head.z_range_mm, lines_per_frame, packing, heights)
    camera, head = station.devices.camera, station.devices.head
    if exposure_ms is not None:
        camera.set_exposure(exposure_ms)
    if speed_mm_s is not None:
        head.set_line_speed(speed_mm_s)
    return _scan(camera, head, plan, rec, t0, "lines", progress, cancel, on_frame,
                 station.record,
                 (lambda: station_room_light(station).image) if room_light else None,
                 roi=region_of_interest(rec, lines))


def _scan(camera: Camera, head: ScanHead, plan, rec: ScanReconstructor, t0: StepTimer,
          what: str, progress: Progress | None, cancel: threading.Event | None,
          on_frame: FrameCallback | None, rig: RigRecord | None = None,
          room_light: Callable[[], np.ndarray | None] | None = None,
          roi: tuple[int, int, int, int] | None = None,
          excess: dict[int, ExcessLight] | None = None) -> ScanResult:
    """The scan loop: ``room_light()`` (the laser-off frame, or None) first — a camera that
    gives none (a trigger only the head sends) leaves the points without grey values, said in the
    summary's ``ambient`` — then the ``plan``'s survey frames (their heights bound the packed
    frames), then its frames: drawn and taken on a thread of their own
    (:class:`~insitu.services.scan_frames.Stream`) while the last ones are reconstructed here, so a
    scan takes the slower of the two (before them a frame with the laser off for each exposure of
    several lines, :func:`~insitu.services.scan_frames.laser_off_frames`, (K − 1)/K of it subtracted
    from those frames; ``excess``: those given, K → the excess, a recording's); the laser off at the
    end, on a cancel (:class:`Cancelled`) or a device fault (:class:`ScanInterrupted`), each keeping
    what was measured. The camera reads ``roi`` only during the lines, and each frame of lines only
    in its own window of one size (:func:`~insitu.services.scan_frames.moving_window`)."""
    ambient, room, taken, packing = "none", None, 0, "one line a frame"
    shot = Shots(camera, head, roi)
    try:
        if room_light is not None:
            try:
                room = room_light()
                ambient = "yes" if room is not None else "none (no room-light frame)"
            except DeviceError as e:
                ambient = f"none (the room-light frame failed: {e})"
            rec.set_ambient(room)
        measured, taken = survey_heights(shot, rec, plan)
        frames = plan.frames(measured)
        packing = describe_packing(plan, frames, measured)
        if excess is None:
            off = laser_off_frames(shot, frames)
            excess = {k: excess_room_light(image, k) for k, image in off.items()}
            taken += len(off)
        if roi is not None:
            shot.follow(moving_window(rec, frames, rec.camera.width, rec.camera.height))
        stream = Stream(shot, frames)
        try:
            for i, f, image in stream:
                if cancel is not None and cancel.is_set():
                    raise Cancelled(f"scan cancelled after {i} of {len(frames)} {what}",
                                    _partial(rec, t0, rig, ambient, taken + i, packing))
                if f.survey:
                    continue
                if len(f.lines) == 1:
                    rec.add(f.ids[0], image, *f.lines[0])
                else:
                    rec.add_lines(image, f.lines, f.ids, plan.z_range, plan.packing,
                                  excess.get(len(f.lines)))
                if on_frame:
                    on_frame(ScanFrame(i, len(frames), image, rec.last_centres,
                                       rec.last_points))
                if progress:
                    progress(i + 1, len(frames))
        except ScanInterrupted as e:
            raise ScanInterrupted(str(e), _partial(rec, t0, rig, ambient, taken, packing)
                                  ) from e.__cause__
        finally:
            stream.close()
        taken += len(frames)
    finally:
        shot.done()
    return _finish(rec, t0, rig, ambient, room, taken, packing)


class RecordedHead:
    """The scan head of a recording: its lines were drawn when the frames were taken."""

    def show_line(self, start, end, focus_z: float = 0.0) -> None:
        """Nothing to draw."""

    def show_lines(self, lines, focus_z: float = 0.0) -> None:
        """Nothing to draw."""

    def off(self) -> None:
        """Nothing is on."""


def save_cloud(result: ScanResult, path: str | Path) -> None:
    if len(result.cloud) == 0:
        raise MeasurementError("the scan gave no points; nothing written")
    write_ply(path, result.cloud)
