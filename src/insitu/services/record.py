"""Recording sequences (docs/formats.md, recorded sequence) on any station: the same four
kinds on a real rig as on the simulated one, frames grabbed exactly as a live run grabs them.
``sequence.json`` carries the operator's rig model; on the simulated rig, ``truth.json`` the
true rig and workpiece beside it (for scoring)."""

from __future__ import annotations

from collections.abc import Callable
from collections.abc import Sequence as Seq
from pathlib import Path

import numpy as np

from insitu.devices.protocols import ExposureCamera, pixel_bits_of
from insitu.errors import ConfigError, DeviceError
from insitu.formats.sequence_writer import SequenceWriter
from insitu.geometry.beams import axis_lines
from insitu.reconstruct.packing import Frame, FramePlan
from insitu.reconstruct.plan import check_region
from insitu.reconstruct.turned_sheet import CROSS_ANGLE_DEG, turned_lines, turned_offset
from insitu.services.common import Progress
from insitu.services.room_light import station_room_light
from insitu.services.scan import plan_lines, reconstructor
from insitu.services.scan_frames import Shots, laser_off_frames, survey_heights
from insitu.services.station import Station

KINDS = ("scan", "height-calibration", "field-calibration", "camera-calibration")
PAPER_HEIGHTS_MM = tuple(float(z) for z in range(-15, 16, 5))
PAPER_OFFSETS_MM = tuple(float(x) for x in range(-30, 31, 5))
NextView = Callable[[int | None], None]
"""Bring the board into view ``i`` (the operator moves it; the simulator places it); None:
the board is put away."""


def _writer(station: Station, out: Path, kind: str, mirrors: bool = False,
            **kw) -> SequenceWriter:
    rig = station.rig
    camera = rig.camera.to_dict() if kind != "camera-calibration" else None
    return SequenceWriter(out, kind, rig.head.spec(mirrors), camera=camera,
                          pixel_bits=pixel_bits_of(station.devices.camera), **kw)


def _exposure(camera, exposure_ms: float | None) -> float | None:
    """Set the camera's exposure when given; the exposure its frames are taken with."""
    if exposure_ms is not None:
        camera.set_exposure(exposure_ms)
    return camera.exposure_ms if isinstance(camera, ExposureCamera) else exposure_ms


def _on_plate(station: Station):
    """The Z stage carrying the plate (ConfigError without one); on the simulated rig the
    parts leave the table first (on a real one the operator clears it)."""
    stage = station.devices.stage
    if stage is None:
        raise ConfigError("a calibration on the plate needs the rig's Z stage (stage: none)")
    if station.world is not None:
        station.world.clear_table()
    return stage


def record_scan(station: Station, out: Path, spacing: float = 0.5, region=None,
                exposure_ms: float | None = None, cross: bool = False,
                progress: Progress | None = None, lines_per_frame: int | str | None = None
                ) -> Path:
    """A scan over ``region`` (x0, x1, y0, y1) mm (default: the station's), a line every
    ``spacing`` mm (``cross``: then a crossed pass, as :func:`~insitu.services.scan.scan_live`
    draws it without a height calibration), after a frame with the laser off under the room
    light (auto-exposed, ``ambient.png``; left out when the camera gives none).
    ``lines_per_frame`` K or "auto": the frames as a live scan packs them
    (:mod:`insitu.reconstruct.packing`; its survey frames first, ``"survey": true``), each
    with its ``lines`` and the exposure it was taken with, and the laser-off frames of their
    exposures (``laser_off``, taken before them as a live scan takes them)."""
    region = tuple(region) if region is not None else station.default_region()
    check_region(region, station.rig.head.field_size_mm)
    lines = plan_lines(region, spacing, cross)
    cam, head, rig = station.devices.camera, station.devices.head, station.rig
    exposure = _exposure(cam, exposure_ms)
    rec = reconstructor(rig.camera, rig.head.pivot_height_mm, rig.head.lens == "telecentric",
                        rig.head.z_range_mm, None, None, "recording")
    plan = FramePlan(lines, rec.sheets, rig.head.z_range_mm, lines_per_frame)
    shot = Shots(cam, head, None)
    with _writer(station, out, "scan", truth=station.truth(region=list(region))) as w:
        def keep(frame: Frame, image: np.ndarray) -> None:
            drawn = [{"start": a.tolist(), "end": b.tolist()} for a, b in frame.lines]
            many = {"lines": drawn} if len(drawn) > 1 else {"line": drawn[0]}
            survey = {"survey": True} if frame.survey else {}
            w.add(image, **many, **survey,
                  exposure_ms=exposure * len(drawn) if exposure is not None else None)
        try:
            try:
                room = station_room_light(station)
                w.add_ambient(room.image, exposure_ms=room.exposure_ms)
            except DeviceError:
                pass            # a camera only the head triggers: a recording without one
            measured, _ = survey_heights(shot, rec, plan, keep)
            frames = plan.frames(measured)
            off = laser_off_frames(shot, frames) if exposure is not None else {}
            for i, f in enumerate(frames):
                keep(f, shot.take(f, i, len(frames), lambda: None))
                if progress:
                    progress(i + 1, len(frames))
            for k, image in off.items():
                w.add_ambient(image, exposure * k, packed=True)
        finally:
            shot.done()
    return out


def record_height_calibration(station: Station, out: Path,
                              heights: Seq[float] = PAPER_HEIGHTS_MM,
                              offsets: Seq[float] = PAPER_OFFSETS_MM, line_y=(-50.0, 50.0),
                              exposure_ms: float | None = None, cross: bool = True,
                              progress: Progress | None = None) -> Path:
    """The flat plate on the stage at each height, a line along y at each offset (Li et al.
    §2.2); with ``cross`` then the crossed lines (:func:`crossed_calibration_lines`) at each
    height again, so the first pass is recorded exactly as without them."""
    stage = _on_plate(station)
    cam, head = station.devices.camera, station.devices.head
    exposure = _exposure(cam, exposure_ms)
    passes = [[(np.array([x, line_y[0]]), np.array([x, line_y[1]])) for x in offsets]]
    if cross:
        passes.append(crossed_calibration_lines(offsets, line_y))
    total, done = len(heights) * sum(map(len, passes)), 0
    with _writer(station, out, "height-calibration", truth=station.truth()) as w:
        try:
            for lines in passes:
                for z in heights:
                    stage.move_z(z)
                    for a, b in lines:
                        head.show_line(a, b)
                        w.add(cam.grab(), line={"start": a.tolist(), "end": b.tolist()},
                              plate_z_mm=float(z), exposure_ms=exposure)
                        done += 1
                        if progress:
                            progress(done, total)
        finally:
            head.off()
    return out


def crossed_calibration_lines(offsets: Seq[float], line_y=(-50.0, 50.0),
                              angle_deg: float = CROSS_ANGLE_DEG
                              ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The crossed lines of a height calibration, (start, end) mm: at ``angle_deg`` to x, as
    far apart as the ``offsets`` of the lines along y and as long, across the whole rectangle
    those lines cover (offsets × ``line_y``), so a crossed scan over it stays calibrated."""
    x = np.unique(np.asarray(offsets, float))
    step = float(np.median(np.diff(x))) if len(x) > 1 else 5.0
    across = max(abs(turned_offset(c, c, angle_deg))
                 for c in ((x[0], line_y[0]), (x[-1], line_y[0]), (x[0], line_y[1]),
                           (x[-1], line_y[1])))
    n = int(np.floor(across / step + 1e-9))
    return turned_lines(step * np.arange(-n, n + 1), line_y, angle_deg)


def record_field_calibration(station: Station, out: Path, n: int = 21, half_mm: float = 90.0,
                             heights: Seq[float] = (0.0,), exposure_ms: float | None = None,
                             progress: Progress | None = None) -> Path:
    """The pilot spot on an n × n grid over ±half_mm on the plate at each of ``heights``
    (world mm; focused there). One height is a field calibration; two or more are what the
    camera's pose recalibration after a move uses (:mod:`insitu.calibrate.pose_from_spots`).
    ``scan_head`` also carries the nominal mirror distance and separation."""
    stage = _on_plate(station)
    cam, head = station.devices.camera, station.devices.head
    exposure = _exposure(cam, exposure_ms)
    grid = np.linspace(-half_mm, half_mm, n)
    spots = [(float(x), float(y)) for y in grid for x in grid]
    total = len(spots) * len(heights)
    with _writer(station, out, "field-calibration", mirrors=True, truth=station.truth()) as w:
        try:
            for z in map(float, heights):
                stage.move_z(z)
                for xy in spots:
                    head.show_spot(np.array(xy), focus_z=z)
                    w.add(cam.grab(), spot=list(xy), plate_z_mm=z, exposure_ms=exposure)
                    if progress:
                        progress(len(w), total)
        finally:
            head.off()
    return out


def record_marked_field_calibration(station: Station, out: Path, n: int = 21,
                                    half_mm: float = 90.0, diameter_mm: float = 2.0,
                                    progress: Progress | None = None) -> Path:
    """The marked-fiducial variant (Mikkelstrup et al. §2.4): circles of ``diameter_mm`` are
    marked, uncorrected, at an n × n grid of commands over ±half_mm on the plate at z = 0,
    then imaged under room light: one frame with the commanded centres (``fiducials``)."""
    from insitu.marking import GalvoDriver, make_job, run_job

    _on_plate(station).move_z(0.0)
    grid = np.linspace(-half_mm, half_mm, n)
    Q = np.array([(x, y) for y in grid for x in grid])
    t = np.linspace(0.0, 2 * np.pi, 97)
    ring = 0.5 * diameter_mm * np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
    job = make_job([ring + [q[0], q[1], 0.0] for q in Q])
    run_job(job, GalvoDriver.from_config(station.rig.head), station.devices.controller,
            progress=progress)
    with _writer(station, out, "field-calibration", truth=station.truth()) as w:
        w.add(station.devices.camera.grab(), fiducials=Q.tolist(),
              fiducial_diameter_mm=float(diameter_mm), plate_z_mm=0.0)
    return out


def record_camera_calibration(station: Station, out: Path, next_view: NextView, views: int,
                              cols: int = 9, rows: int = 6, square_mm: float = 10.0,
                              axis_lines: Seq[tuple[np.ndarray, np.ndarray]] = (),
                              plate_z: float = 0.0, reference: bool = True,
                              truth: dict | None = None,
                              progress: Progress | None = None) -> Path:
    """``views`` checkerboard views (``next_view(i)`` brings view i), then with
    ``axis_lines`` the camera ↔ scan-head alignment (Li et al. Case 1 step 1): the board
    flat on the plate at ``plate_z`` (``next_view(views)``), a laser-off frame of it
    (``reference``) and one frame per line drawn on it; ``next_view(None)`` at the end.
    ``truth``: added to the station's."""
    board = {"cols": cols, "rows": rows, "square_mm": square_mm}
    cam, head = station.devices.camera, station.devices.head
    total = views + len(axis_lines) + int(bool(axis_lines) and reference)
    truth = station.truth(**(truth or {}))
    with _writer(station, out, "camera-calibration", checkerboard=board, truth=truth) as w:
        for i in range(views):
            next_view(i)
            w.add(cam.grab())
            if progress:
                progress(i + 1, total)
        if axis_lines:
            next_view(views)
            if reference:
                w.add(cam.grab(), plate_z_mm=plate_z)
            try:
                for a, b in axis_lines:
                    head.show_line(a, b)
                    w.add(cam.grab(), line={"start": list(map(float, a)),
                                            "end": list(map(float, b))}, plate_z_mm=plate_z)
                    if progress:
                        progress(len(w), total)
            finally:
                head.off()
    next_view(None)
    return out


def record(station: Station, kind: str, out: Path, *, spacing: float = 0.5, region=None,
           cross: bool | None = None, grid: int = 21, heights: Seq[float] = (0.0,),
           marked: bool = False,
           next_view: NextView | None = None, views: int = 15, truth: dict | None = None,
           alignment: bool = True, progress: Progress | None = None,
           lines_per_frame: int | str | None = None) -> Path:
    """A sequence of ``kind`` (one of :data:`KINDS`) with the options that kind takes:
    a scan (``spacing``, ``region``, ``lines_per_frame``), the height calibration, the field
    calibration (``grid`` spots per side at ``heights``, or ``marked`` circles), the camera
    calibration (``views`` brought by ``next_view``, then with ``alignment`` the board flat on the
    plate and the head's axis lines on it, which give the camera's pose in the scan-head frame;
    ``truth``: added to the station's). ``cross``: a scan's crossed pass (default off), the height
    calibration's crossed lines (default on)."""
    if kind == "scan":
        return record_scan(station, out, spacing, region, cross=bool(cross), progress=progress,
                           lines_per_frame=lines_per_frame)
    if kind == "height-calibration":
        return record_height_calibration(station, out, cross=cross is not False,
                                          progress=progress)
    if kind == "field-calibration" and marked:
        return record_marked_field_calibration(station, out, n=grid, progress=progress)
    if kind == "field-calibration":
        return record_field_calibration(station, out, n=grid, heights=heights,
                                        progress=progress)
    if kind == "camera-calibration" and next_view is not None:
        return record_camera_calibration(station, out, next_view, views, truth=truth,
                                         axis_lines=axis_lines() if alignment else (),
                                         progress=progress)
    raise ConfigError(f"KIND {kind!r}: expected one of {', '.join(KINDS)}"
                      + (" (a camera calibration needs someone to move the board)"
                         if kind == "camera-calibration" else ""))
