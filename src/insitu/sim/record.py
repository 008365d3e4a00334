"""Recorded sequences from the simulated rig (formats.md §1), with ``truth.json`` beside them.

Frames come from the sim devices exactly as a live run grabs them; ``sequence.json`` carries
the operator's calibration (with its errors), ``truth.json`` the true rig and workpiece.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence as Seq
from pathlib import Path

import numpy as np

from insitu.devices.sim import SimCamera, SimScanHead, SimStage, SimWorld
from insitu.formats.sequence import SequenceWriter
from insitu.sim.checkerboard import random_board_poses, render_checkerboard
from insitu.sim.render import NOMINAL_EXPOSURE_MS

Progress = Callable[[int, int], None]
KINDS = ("scan", "height-calibration", "field-calibration", "camera-calibration")
PAPER_HEIGHTS_MM = tuple(float(z) for z in range(-15, 16, 5))
PAPER_OFFSETS_MM = tuple(float(x) for x in range(-30, 31, 5))


def scan_lines(region: Seq[float], spacing: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Lines along y over region (x0, x1, y0, y1), mm, one every ``spacing`` mm along x."""
    x0, x1, y0, y1 = map(float, region)
    n = int(np.floor((x1 - x0) / spacing + 1e-9)) + 1
    return [(np.array([x, y0]), np.array([x, y1])) for x in x0 + spacing * np.arange(n)]


def default_region(world: SimWorld, margin: float = 3.0) -> tuple[float, float, float, float]:
    """The parts' footprint plus a margin, mm."""
    if not world.parts:
        return (-20.0, 20.0, -45.0, 45.0)
    lo = np.min([p.bounds()[0] for p in world.parts], axis=0)
    hi = np.max([p.bounds()[1] for p in world.parts], axis=0)
    return (lo[0] - margin, hi[0] + margin, lo[1] - 2 * margin, hi[1] + 2 * margin)


def _truth(world: SimWorld, **extra) -> dict:
    return {"rig": world.rig.truth_dict(),
            "workpieces": [{"name": p.name, "params": p.params} for p in world.parts], **extra}


def _writer(world: SimWorld, out: Path, kind: str, **kw) -> SequenceWriter:
    rig = world.rig
    camera = rig.operator_camera.to_dict() if kind != "camera-calibration" else None
    return SequenceWriter(out, kind, rig.nominal.to_dict(), camera=camera, **kw)


def record_scan(world: SimWorld, out: Path, spacing: float = 0.5, region=None,
                exposure_ms: float = NOMINAL_EXPOSURE_MS, progress: Progress | None = None) -> Path:
    region = tuple(region) if region is not None else default_region(world)
    lines = scan_lines(region, spacing)
    cam, head = SimCamera(world), SimScanHead(world)
    cam.set_exposure(exposure_ms)
    with _writer(world, out, "scan", truth=_truth(world, region=list(region))) as w:
        for i, (a, b) in enumerate(lines):
            head.show_line(a, b)
            w.add(cam.grab(), line={"start": a.tolist(), "end": b.tolist()},
                  exposure_ms=exposure_ms)
            if progress:
                progress(i + 1, len(lines))
        head.off()
    return out


def record_height_calibration(world: SimWorld, out: Path,
                              heights: Seq[float] = PAPER_HEIGHTS_MM,
                              offsets: Seq[float] = PAPER_OFFSETS_MM, line_y=(-50.0, 50.0),
                              exposure_ms: float = NOMINAL_EXPOSURE_MS,
                              progress: Progress | None = None) -> Path:
    """The flat plate on the stage at each height, a line at each offset (Li et al. §2.2)."""
    world.parts = []
    cam, head, stage = SimCamera(world), SimScanHead(world), SimStage(world)
    cam.set_exposure(exposure_ms)
    total, done = len(heights) * len(offsets), 0
    with _writer(world, out, "height-calibration", truth=_truth(world)) as w:
        for z in heights:
            stage.move_z(z)
            for x in offsets:
                a, b = np.array([x, line_y[0]]), np.array([x, line_y[1]])
                head.show_line(a, b)
                w.add(cam.grab(), line={"start": a.tolist(), "end": b.tolist()},
                      plate_z_mm=float(z), exposure_ms=exposure_ms)
                done += 1
                if progress:
                    progress(done, total)
        head.off()
    return out


def record_field_calibration(world: SimWorld, out: Path, n: int = 21, half_mm: float = 90.0,
                             heights: Seq[float] = (0.0,),
                             exposure_ms: float = NOMINAL_EXPOSURE_MS,
                             progress: Progress | None = None) -> Path:
    """The pilot spot on an n × n grid over ±half_mm on the plate at each of ``heights``
    (world mm; focused there). One height is a field calibration; two or more are what the
    camera's pose recalibration after a move uses (:mod:`insitu.calibrate.pose_from_spots`).
    ``scan_head`` also carries the nominal mirror distance and separation."""
    world.parts = []
    rig = world.rig
    cam, head, stage = SimCamera(world), SimScanHead(world), SimStage(world)
    cam.set_exposure(exposure_ms)
    grid = np.linspace(-half_mm, half_mm, n)
    spots = [(float(x), float(y)) for y in grid for x in grid]
    head_spec = {**rig.nominal.to_dict(), "mirror_distance_mm": rig.nominal.mirror_distance_mm,
                 "mirror_separation_mm": rig.nominal.mirror_separation_mm}
    total = len(spots) * len(heights)
    with SequenceWriter(out, "field-calibration", head_spec,
                        camera=rig.operator_camera.to_dict(), truth=_truth(world)) as w:
        for z in map(float, heights):
            stage.move_z(z)
            for xy in spots:
                head.show_spot(np.array(xy), focus_z=z)
                w.add(cam.grab(), spot=list(xy), plate_z_mm=z, exposure_ms=exposure_ms)
                if progress:
                    progress(len(w), total)
        head.off()
    return out


def record_marked_field_calibration(world: SimWorld, out: Path, n: int = 21,
                                    half_mm: float = 90.0, diameter_mm: float = 2.0,
                                    progress: Progress | None = None) -> Path:
    """The marked-fiducial variant (Mikkelstrup et al. §2.4): circles of ``diameter_mm`` are
    marked, uncorrected, at an n × n grid of commands over ±half_mm on the plate at z = 0,
    then imaged under room light: one frame with the commanded centres (``fiducials``)."""
    from insitu.devices.sim_marking import SimController, SimInspectionCamera
    from insitu.marking import GalvoDriver, make_job, run_job

    world.parts = []
    SimStage(world).move_z(0.0)
    grid = np.linspace(-half_mm, half_mm, n)
    Q = np.array([(x, y) for y in grid for x in grid])
    t = np.linspace(0.0, 2 * np.pi, 97)
    ring = 0.5 * diameter_mm * np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
    job = make_job([ring + [q[0], q[1], 0.0] for q in Q])
    run_job(job, GalvoDriver.from_config(world.rig.nominal), SimController(world),
            progress=progress)
    with _writer(world, out, "field-calibration", truth=_truth(world)) as w:
        w.add(SimInspectionCamera(world).grab(), fiducials=Q.tolist(),
              fiducial_diameter_mm=float(diameter_mm), plate_z_mm=0.0)
    return out


def record_camera_calibration(world: SimWorld, out: Path, views: int = 15, cols: int = 9,
                              rows: int = 6, square_mm: float = 10.0,
                              progress: Progress | None = None) -> Path:
    """Checkerboard views at random poses in front of the true camera."""
    rng = np.random.default_rng(world.seed + 7)
    camera = world.rig.camera
    poses = random_board_poses(camera, cols, rows, square_mm, views, rng)
    truth = _truth(world, board_poses=[{"R": R.tolist(), "t": t.tolist()} for R, t in poses])
    board = {"cols": cols, "rows": rows, "square_mm": square_mm}
    with _writer(world, out, "camera-calibration", checkerboard=board, truth=truth) as w:
        for i, (R, t) in enumerate(poses):
            w.add(render_checkerboard(camera, R, t, cols, rows, square_mm, rng))
            if progress:
                progress(i + 1, len(poses))
    return out
