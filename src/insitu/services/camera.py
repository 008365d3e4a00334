"""Camera calibration use cases: intrinsics (and the world pose) from a recorded
camera-calibration folder; the pose alone, after the camera moved, from laser spots; the
calibration file with its picture beside it.

A camera-calibration sequence (docs/formats.md) holds checkerboard views (frames with only
``file``). It may also hold alignment frames — the board lying on the plate, frames carrying
``plate_z_mm`` — as :func:`insitu.services.record.record_camera_calibration` records them:
one laser-off frame (no ``line``; it is also a calibration view) and frames of the head's
axis lines (``line``). With them the camera's pose in the world (scan-head) frame is computed
(:mod:`insitu.calibrate.alignment`); without, the extrinsics stay R = I, t = 0 and the notes say so.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from insitu.calibrate.alignment import Alignment, LineFrame, align_to_head
from insitu.calibrate.camera import (
    INTRINSIC_NAMES,
    BoardSpec,
    Detection,
    Intrinsics,
    board_pose,
    calibrate_intrinsics,
    detect_board,
)
from insitu.calibrate.photos import image_files, read_grey
from insitu.calibrate.pose_from_spots import PoseFromSpots, SpotObservations, pose_from_spots
from insitu.errors import CalibrationError, InsituError
from insitu.formats.calibration import CameraCalibration
from insitu.formats.json_file import load_json_model
from insitu.formats.rig import ScanHeadConfig
from insitu.formats.sequence import Sequence
from insitu.geometry.beams import BeamModel, PivotHead, ScanHeadOptics, TwoMirrorHead
from insitu.geometry.camera import CameraModel
from insitu.services.common import Progress, camera_model, save_with_picture


def _prefixed(folder, e: InsituError) -> CalibrationError:
    return CalibrationError(f"{folder}: {e}")


# -- intrinsics (+ alignment) ---------------------------------------------------------------
def detect_views(seq: Sequence, board: BoardSpec, progress: Progress | None = None
                 ) -> tuple[list[int], list[Detection | None], tuple[int, int]]:
    """Board detection in every frame without a ``line``: (frame indices, detections or None,
    image size (W, H)). FormatError if the frames differ in size."""
    idx = [i for i, f in enumerate(seq.frames) if f.line is None]
    views = ((seq.folder / seq.frames[i].file, seq.read_frame(i)) for i in idx)
    dets, size = _detect_all(views, board, len(idx) + 1, progress)
    return idx, dets, size


def _detect_all(views, board: BoardSpec, total: int, progress: Progress | None
                ) -> tuple[list[Detection | None], tuple[int, int]]:
    """Board detection in each (where, image) of ``views``, one image in memory at a time:
    detections (or None) and the image size (W, H); CalibrationError when sizes differ."""
    dets, size = [], None
    for n, (where, img) in enumerate(views):
        if size is None:
            size = (img.shape[1], img.shape[0])
        elif (img.shape[1], img.shape[0]) != size:
            raise CalibrationError(f"{where}: image is {img.shape[1]}x{img.shape[0]} pixels, "
                                   f"earlier images are {size[0]}x{size[1]}")
        dets.append(detect_board(img, board))
        if progress:
            progress(n + 1, total)
    return dets, size


def _alignment(seq: Sequence, board: BoardSpec, intr: Intrinsics, idx: list[int],
               dets: list[Detection | None]) -> tuple[Alignment, dict] | None:
    """The world pose from the alignment frames, or None when the sequence has no line frames."""
    frames = seq.frames
    line_idx = [i for i, f in enumerate(frames) if f.line is not None]
    if not line_idx:
        return None
    folder = seq.folder
    heights = {frames[i].plate_z_mm for i in line_idx}
    heights |= {f.plate_z_mm for f in frames if f.line is None and f.plate_z_mm is not None}
    heights.discard(None)
    if len(heights) > 1:
        raise CalibrationError(f"{folder}: alignment frames at several plate heights "
                               f"{sorted(heights)} mm; expected one board placement")
    plate_z = float(heights.pop()) if heights else 0.0
    refs = [i for i, f in enumerate(frames) if f.line is None and f.plate_z_mm is not None]
    det_of = dict(zip(idx, dets))
    reference = None
    for i in refs:                               # the laser-off frame: pose and difference
        if det_of.get(i) is not None:
            reference, det, where = seq.read_frame(i), det_of[i], frames[i].file
            break
    else:                                        # none: the board in a line frame
        for i in line_idx:
            det = detect_board(seq.read_frame(i), board)
            if det is not None:
                where = frames[i].file
                break
        else:
            raise CalibrationError(f"{folder}: alignment frames: no {board.describe()} found "
                                   "in the laser-off frame nor in any line frame")
    R_cb, t_cb, pnp_rms = board_pose(det, intr.K, intr.dist)
    lines = [LineFrame(seq.read_frame(i), np.array(frames[i].line.start),
                       np.array(frames[i].line.end), frames[i].file) for i in line_idx]
    try:
        al = align_to_head(lines, reference, board, intr.K, intr.dist, R_cb, t_cb, plate_z)
    except CalibrationError as e:
        raise _prefixed(folder, e) from None
    info = {"board_frame": where, "board_pnp_rms_px": pnp_rms, "plate_z_mm": plate_z,
            "reference": reference is not None, "angle_deg": al.angle_deg,
            "line_rms_mm": al.line_rms_mm, "line_points": al.points,
            "R_board_world": al.R_board_world.tolist(), "t_board_world": al.t_board_world.tolist()}
    return al, info


def _intrinsics(folder, dets: list[Detection | None], names: list[str], size, board: BoardSpec,
                outlier_factor: float, what: str, noun: str) -> Intrinsics:
    if all(d is None for d in dets):
        raise CalibrationError(f"{folder}: no {board.describe()} found in any of the "
                               f"{len(dets)} {noun}; check {what} (cols and rows count inner "
                               "corners)")
    try:
        return calibrate_intrinsics(dets, size, names, outlier_factor)
    except CalibrationError as e:
        raise _prefixed(folder, e) from None


def _result(folder, board: BoardSpec, intr: Intrinsics, size,
            found: tuple[Alignment, dict] | None) -> CameraCalibration:
    rejected = intr.rejected
    notes = [f"{len(intr.used)} of {len(intr.views)} views used, {board.describe()}"]
    if rejected:
        notes.append("rejected: " + "; ".join(f"{v.name} ({v.reason})" for v in rejected))
    residuals = {"rms_px": intr.rms_px,
                 "max_view_rms_px": max(v.rms_px for v in intr.used),
                 "views_used": float(len(intr.used)), "views_rejected": float(len(rejected))}
    extra = {}
    if found is None:
        R, t = np.eye(3), np.zeros(3)
        notes.append("no alignment frames: extrinsics left at R = I, t = 0 (world = camera "
                     "frame); record the head's axis lines on the board to get the world pose")
    else:
        al, info = found
        R, t = al.R, al.t
        residuals.update(al.summary())
        extra["alignment"] = info
        notes.append(f"world pose from the head's axis lines on the board (lines at "
                     f"{al.angle_deg:.3f}°, centres {al.line_rms_mm:.4f} mm RMS about them)")
    camera = {"width": size[0], "height": size[1], "K": intr.K.tolist(),
              "dist": intr.dist.tolist(), "R": R.tolist(), "t": t.tolist()}
    return CameraCalibration(
        camera=camera, rms_px=intr.rms_px, per_view_rms_px=[v.rms_px for v in intr.used],
        std_intrinsics=intr.std.tolist(), inputs=[str(folder)], residuals=residuals,
        notes="; ".join(notes), std_intrinsics_order=list(INTRINSIC_NAMES[:len(intr.std)]),
        views=[{"file": v.name, "used": v.used, "rms_px": v.rms_px, "reason": v.reason,
                "detector": v.detector} for v in intr.views], **extra)


def calibrate_photos(folder: str | Path, board: BoardSpec | None,
                     progress: Progress | None = None,
                     outlier_factor: float = 3.0) -> CameraCalibration:
    """Intrinsics from a plain folder of board photos (:mod:`insitu.calibrate.photos`); the
    extrinsics stay R = I, t = 0. CalibrationError (one line) on bad input."""
    files = image_files(folder)
    if board is None:
        raise CalibrationError(f"{folder}: no sequence.json; give the board "
                               "(COLSxROWSxSQUARE_MM, e.g. 9x6x25)")
    dets, size = _detect_all(((f, read_grey(f)) for f in files), board, len(files), progress)
    intr = _intrinsics(folder, dets, [p.name for p in files], size, board, outlier_factor,
                       "the board", "images")
    return _result(folder, board, intr, size, None)


def calibrate_camera(folder: str | Path, progress: Progress | None = None,
                     outlier_factor: float = 3.0, board: BoardSpec | None = None
                     ) -> CameraCalibration:
    """Intrinsics from a recorded camera-calibration folder, and the world pose if it holds
    alignment frames; a folder without sequence.json → :func:`calibrate_photos` with
    ``board``. A ``board`` that disagrees with the sequence's checkerboard is refused.
    CalibrationError (one line, naming the folder) on bad input."""
    if Path(folder).is_dir() and not (Path(folder) / "sequence.json").exists():
        return calibrate_photos(folder, board, progress, outlier_factor)
    seq = Sequence.open(folder)
    if seq.kind != "camera-calibration":
        raise CalibrationError(f"{seq.folder}: a '{seq.kind}' sequence, not a camera calibration")
    try:
        recorded = BoardSpec.from_spec(seq.checkerboard)
    except CalibrationError as e:
        raise _prefixed(seq.folder / "sequence.json", e) from None
    if board is not None and board != recorded:
        raise CalibrationError(f"board: {board.describe()}, but {seq.folder / 'sequence.json'}"
                               f" records a {recorded.describe()}; leave the board out",
                               field="board")
    board = recorded
    idx, dets, size = detect_views(seq, board, progress)
    if not idx:
        raise CalibrationError(f"{seq.folder}: no checkerboard views (every frame has a line)")
    intr = _intrinsics(seq.folder, dets, [seq.frames[i].file for i in idx], size, board,
                       outlier_factor, "sequence.json checkerboard", "frames")
    found = _alignment(seq, board, intr, idx, dets)
    if progress:
        progress(len(idx) + 1, len(idx) + 1)
    return _result(folder, board, intr, size, found)


# -- pose from spots (recalibration after the camera moved) --------------------------------
def head_beams(seq: Sequence, scan_head: str | Path | None = None,
               field: str | Path | None = None) -> tuple[BeamModel, str]:
    """The beams to use: the nominal two-mirror head of a scan-head config file (else of the
    sequence's ``scan_head`` if it carries mirror_distance_mm / mirror_separation_mm, else a
    pivot head at pivot_height_mm), corrected by a field correction file if given."""
    if scan_head is not None:
        cfg = load_json_model(scan_head, ScanHeadConfig)
        beams, what = (TwoMirrorHead.of(cfg),
                       f"two-mirror head of {scan_head}")
    else:
        extra = seq.scan_head.model_extra or {}
        if "mirror_distance_mm" in extra:
            d, e = float(extra["mirror_distance_mm"]), float(extra.get("mirror_separation_mm", 0))
            beams, what = TwoMirrorHead(d, e), "two-mirror head of the sequence's scan_head"
        else:
            H = seq.scan_head.pivot_height_mm
            beams = PivotHead(H, seq.scan_head.lens == "telecentric")
            what = f"pivot head (H = {H:g} mm) of the sequence's scan_head"
    if field is not None:
        from insitu.calibrate.field_file import load_field_correction

        beams = ScanHeadOptics(beams, load_field_correction(field).delta())
        what += f", field distortion of {field}"
    return beams, what


def spot_observations(seq: Sequence, progress: Progress | None = None
                      ) -> tuple[SpotObservations, list[str]]:
    """Spot centres of every spot frame; frames without a usable spot are skipped (listed)."""
    from insitu.vision.spots import find_spot

    frames = [(i, f) for i, f in enumerate(seq.frames) if f.spot is not None]
    cmd, z, uv, skipped = [], [], [], []
    for n, (i, f) in enumerate(frames):
        if f.plate_z_mm is None:
            raise CalibrationError(f"{seq.folder}: frames[{i}].plate_z_mm: missing (the spots' "
                                   "plate height is needed)")
        try:
            s = find_spot(seq.read_frame(i), where=str(seq.folder / f.file))
        except CalibrationError as e:
            skipped.append(str(e))
        else:
            cmd.append(f.spot)
            z.append(f.plate_z_mm)
            uv.append(s.uv)
        if progress:
            progress(n + 1, len(frames))
    if not frames:
        raise CalibrationError(f"{seq.folder}: no spot frames (frames with 'spot')")
    if len(uv) < 0.5 * len(frames):
        raise CalibrationError(f"{seq.folder}: a spot was found in only {len(uv)} of "
                               f"{len(frames)} frames; first problem: {skipped[0]}")
    return SpotObservations(np.array(cmd), np.array(z), np.array(uv)), skipped


def pose_change(a: CameraModel, b: CameraModel) -> tuple[float, float]:
    """How far camera ``b`` is from camera ``a``: rotation angle, degrees, and distance of
    the centres, mm."""
    c = np.clip((np.trace(b.R @ a.R.T) - 1) / 2, -1.0, 1.0)
    return float(np.degrees(np.arccos(c))), float(np.linalg.norm(b.centre_world - a.centre_world))


def recalibrate_camera_pose(folder: str | Path, intrinsics: str | Path | None = None,
                            scan_head: str | Path | None = None, field: str | Path | None = None,
                            progress: Progress | None = None) -> CameraCalibration:
    """The camera's new pose from spots on the plate at two (or more) heights (a
    field-calibration-like sequence: frames with ``spot`` and ``plate_z_mm``). Intrinsics:
    from ``intrinsics`` (a CAMERA.json) or the sequence's ``camera``; the pose found replaces
    theirs."""
    seq = Sequence.open(folder)
    if intrinsics is not None:
        cal = load_json_model(intrinsics, CameraCalibration)
        spec, source = cal.camera, str(intrinsics)
    elif seq.camera is not None:
        spec, source = seq.camera, f"{folder} (sequence camera)"
    else:
        raise CalibrationError(f"{folder}: no camera intrinsics (give a camera calibration file)")
    camera = camera_model(spec)
    first = next((i for i, f in enumerate(seq.frames) if f.spot is not None), None)
    if first is not None:
        h, w = seq.read_frame(first).shape[:2]
        if (w, h) != (camera.width, camera.height):
            raise CalibrationError(f"{seq.folder / seq.frames[first].file}: image is {w}x{h} "
                                   f"pixels, the camera of {source} is "
                                   f"{camera.width}x{camera.height}")
    beams, what = head_beams(seq, scan_head, field)
    obs, skipped = spot_observations(seq, progress)
    try:
        res: PoseFromSpots = pose_from_spots(obs, camera, beams)
    except CalibrationError as e:
        raise _prefixed(folder, e) from None
    heights = sorted(set(obs.plate_z.tolist()))
    cam = CameraModel(camera.width, camera.height, camera.K, camera.dist, res.R, res.t)
    turned, moved = pose_change(camera, cam)
    notes = (f"pose from {len(obs.uv)} spots on the plate at {', '.join(f'{h:g}' for h in heights)}"
             f" mm (beams: {what}); intrinsics of {source}; the camera turned {turned:.3f}° and "
             f"moved {moved:.2f} mm from the pose there")
    if skipped:
        notes += f"; {len(skipped)} frames without a usable spot skipped"
    kept = ({"rms_px": cal.rms_px, "per_view_rms_px": cal.per_view_rms_px,
             "std_intrinsics": cal.std_intrinsics} if intrinsics is not None else {})
    return CameraCalibration(
        camera=cam.to_dict(), inputs=[str(folder)] + ([str(intrinsics)] if intrinsics else []),
        residuals={"point_to_beam_rms_mm": res.rms_mm,
                   "point_to_beam_max_mm": float(res.residuals_mm.max()),
                   "spots": float(len(obs.uv)),
                   "pose_std_rotation_deg": float(np.linalg.norm(res.std_rot_deg)),
                   "pose_std_translation_mm": float(np.linalg.norm(res.std_t_mm))},
        notes=notes, pose_std_rotvec_deg=res.std_rot_deg.tolist(),
        pose_std_t_mm=res.std_t_mm.tolist(), pose_change={"rotation_deg": turned,
                                                          "centre_mm": moved}, **kept)


def calibrate_camera_recording(folder: str | Path, intrinsics: str | Path | None = None,
                               scan_head: str | Path | None = None,
                               field: str | Path | None = None,
                               progress: Progress | None = None,
                               board: BoardSpec | None = None) -> CameraCalibration:
    """``insitu calibrate camera``: a camera-calibration folder or a plain folder of board
    photos → :func:`calibrate_camera`; a folder of spots at two plate heights →
    :func:`recalibrate_camera_pose`."""
    if Path(folder).is_dir() and not (Path(folder) / "sequence.json").exists():
        return calibrate_photos(folder, board, progress)
    seq = Sequence.open(folder)
    if seq.kind == "camera-calibration":
        return calibrate_camera(folder, progress, board=board)
    if board is not None:
        raise CalibrationError(f"board: {folder} is a '{seq.kind}' sequence, not board views",
                               field="board")
    if any(f.spot is not None for f in seq.frames):
        return recalibrate_camera_pose(folder, intrinsics, scan_head, field, progress)
    raise CalibrationError(f"{folder}: a '{seq.kind}' sequence without spots: expected a "
                           "camera-calibration folder, or spots on the plate at two heights")


def camera_report_png(cal: CameraCalibration, folder: str | Path, path: str | Path) -> None:
    """Write the calibration's picture: the reprojection RMS of each view as bars, or, for a
    pose from spots without them, the middle frame of the recorded ``folder``."""
    from insitu.calibrate.report import bars_image, write_report_png

    if cal.per_view_rms_px:
        image = bars_image(cal.per_view_rms_px, f"reprojection RMS per view, px (all: "
                                                f"{cal.rms_px:.3f} px)")
    else:
        seq = Sequence.open(folder)
        image = seq.read_frame(len(seq) // 2)
        if image.dtype != np.uint8:
            image = (image >> 8).astype(np.uint8)
    write_report_png(path, image)


def calibrate_camera_and_report(folder: str | Path, out: str | Path,
                                intrinsics: str | Path | None = None,
                                scan_head: str | Path | None = None,
                                field: str | Path | None = None,
                                progress: Progress | None = None,
                                board: BoardSpec | None = None) -> CameraCalibration:
    """:func:`calibrate_camera_recording`, then write ``out`` (JSON) and its picture beside
    it (.png, :func:`camera_report_png`); nothing is left behind if either fails."""
    cal = calibrate_camera_recording(folder, intrinsics, scan_head, field, progress, board)
    save_with_picture(out, cal, lambda png: camera_report_png(cal, folder, png))
    return cal
