"""Height calibration use cases: fit from a recorded sequence, save, load."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from insitu.calibrate.height_fit import (
    LineObservation,
    cross_validate_sheet,
    fit_paper,
    fit_sheet,
    fit_turned_sheet,
    height_residuals,
    residual_grid,
)
from insitu.errors import CalibrationError, ConfigError, MeasurementError
from insitu.formats.calibration import HeightCalibration, ResidualGridSpec
from insitu.formats.json_file import load_json_model
from insitu.formats.sequence import Sequence
from insitu.formats.validation import one_of, show
from insitu.geometry.camera import CameraModel
from insitu.reconstruct.height_models import HEIGHT_MODELS, HeightModel
from insitu.reconstruct.plane import expected_band, line_runs_along_rows
from insitu.reconstruct.turned_sheet import (
    TurnedSheetModel,
    line_angle,
    same_direction,
    turned_camera,
    turned_offset,
)
from insitu.services.common import Progress, camera_model, save_with_picture
from insitu.vision.centres import CENTRE_METHODS
from insitu.vision.extract import CentreSettings, extract_centres


def observations(seq: Sequence, settings: CentreSettings = CentreSettings(),
                 progress: Progress | None = None
                 ) -> tuple[list[LineObservation], list[LineObservation], float | None]:
    """Line centres of every frame of a height-calibration sequence, one frame at a time,
    each line (a frame may hold several) searched where its light plane meets the plate
    (± 3 mm): (the frames of lines along
    y, each at its x; the crossed frames, each at its offset in the turned frame
    (:mod:`insitu.reconstruct.turned_sheet`); the crossed lines' angle to x, None without)."""
    if seq.kind != "height-calibration":
        raise CalibrationError(f"{seq.folder}: a '{seq.kind}' sequence, not a height calibration")
    camera, H = camera_model(seq.camera), seq.scan_head.pivot_height_mm
    along_y, crossed, angle = [], [], None
    for i, frame, image in seq:
        for a, b in frame.drawn():             # a frame's lines lie apart on the plate
            if abs(a[0] - b[0]) > 1e-9:
                angle = line_angle(a, b) if angle is None else angle
                if not same_direction(a, b, angle):
                    raise CalibrationError(
                        f"{seq.folder}: frames[{i}].line: expected lines along y or crossed "
                        f"lines at {angle:g}° to x (as the earlier frames), got "
                        f"{line_angle(a, b):g}°")
            rows = line_runs_along_rows(camera, a, b)
            plate = (frame.plate_z_mm - 3.0, frame.plate_z_mm + 3.0)
            band = expected_band(camera, a, b, H, plate, along_rows=rows)
            c = extract_centres(image, settings, band, rows, pixel_bits=seq.pixel_bits)
            if len(c) < 20:
                raise CalibrationError(f"{seq.folder}: {frame.file}: no laser line found "
                                       f"(line {list(a)} → {list(b)} mm, plate at "
                                       f"{frame.plate_z_mm:g} mm)")
            if abs(a[0] - b[0]) > 1e-9:
                crossed.append(LineObservation(turned_offset(a, b, angle),
                                               float(frame.plate_z_mm), c.u, c.v))
            else:
                along_y.append(LineObservation(float(a[0]), float(frame.plate_z_mm), c.u, c.v))
        if progress:
            progress(i + 1, len(seq))
    return along_y, crossed, angle


def calibrate_height(folder: str | Path, settings: CentreSettings = CentreSettings(),
                     progress: Progress | None = None) -> HeightCalibration:
    """Fit both height models from a recorded height-calibration folder; ours is the default."""
    seq = Sequence.open(folder)
    camera = camera_model(seq.camera)
    H = seq.scan_head.pivot_height_mm
    obs, crossed, angle = observations(seq, settings, progress)
    sheet = fit_sheet(obs, camera, H)
    residuals = {f"sheet_{k}": v for k, v in height_residuals(sheet, camera, obs).items()}
    residuals.update({f"sheet_{k}": v for k, v in cross_validate_sheet(obs, camera, H).items()})
    paper = None
    if any(o.x_mm == 0.0 and o.z_mm == 0.0 for o in obs):
        paper = fit_paper(obs)
        residuals.update({f"paper_{k}": v for k, v in height_residuals(paper, camera, obs).items()})
    cross = None
    if crossed:
        cross = fit_turned_sheet(crossed, camera, H, angle)
        tcam = turned_camera(camera, angle)
        residuals.update({f"sheet_cross_{k}": v for k, v in
                          height_residuals(cross.sheet, tcam, crossed).items()})
        residuals.update({f"sheet_cross_{k}": v for k, v in
                          cross_validate_sheet(crossed, tcam, H).items()})
    heights, offsets, rms = residual_grid(sheet, camera, obs)
    grid = ResidualGridSpec(heights_mm=heights.tolist(), offsets_mm=offsets.tolist(),
                            rms_mm=[[float(v) if np.isfinite(v) else None for v in row]
                                    for row in rms])
    return HeightCalibration(
        camera=seq.camera, centres=settings.to_dict(), model="sheet", sheet=sheet.to_dict(),
        paper=paper.to_dict() if paper else None,
        sheet_cross=cross.to_dict() if cross else None, inputs=[str(Path(folder))],
        residuals=residuals, residual_grid=grid,
        notes=f"{len(obs)} frames: plate at {heights[0]:g} … {heights[-1]:g} mm "
              f"({len(heights)} heights), lines at {offsets[0]:g} … {offsets[-1]:g} mm "
              f"({len(offsets)} offsets)"
              + (f"; {len(crossed)} frames of crossed lines at {angle:g}° to x" if cross else ""))


def height_report_png(cal: HeightCalibration, path: str | Path) -> None:
    """Write the picture of the calibration's residual grid (plate height × line offset)."""
    from insitu.calibrate.report import grid_image, write_report_png

    g = cal.residual_grid
    if g is None:
        raise CalibrationError(f"{path}: the height calibration has no residual grid to draw")
    rms = np.array([[np.nan if v is None else v for v in row] for row in g.rms_mm], float)
    r = cal.residuals
    title = (f"height calibration ({cal.model}): RMS {r.get('sheet_rms_mm', np.nan):.4f} mm, "
             f"max {r.get('sheet_max_mm', np.nan):.4f} mm; per frame RMS in µm")
    write_report_png(path, grid_image(np.array(g.heights_mm), np.array(g.offsets_mm), rms,
                                      title))


def calibrate_height_and_report(folder: str | Path, out: str | Path,
                                progress: Progress | None = None) -> HeightCalibration:
    """:func:`calibrate_height`, then write ``out`` (JSON) and the residual grid's picture
    beside it (.png); nothing is left behind if either fails."""
    cal = calibrate_height(folder, progress=progress)
    save_with_picture(out, cal, lambda png: height_report_png(cal, png))
    return cal


def load_height_calibration(path: str | Path, progress: Progress | None = None
                            ) -> HeightCalibration:
    """A height calibration file, or a recorded height-calibration folder (fitted now).
    ConfigError naming the file and field for a ``model`` not in :data:`HEIGHT_MODELS` or a
    ``centres.method`` not in :data:`CENTRE_METHODS`."""
    path = Path(path)
    if path.is_dir():
        return calibrate_height(path, progress=progress)
    cal = load_json_model(path, HeightCalibration)
    for field, value, table in (("model", cal.model, HEIGHT_MODELS),
                                ("centres.method", cal.centres.method, CENTRE_METHODS)):
        if value not in table:
            raise ConfigError(f"{path}: {field}: expected {one_of(table)}, got {show(value)}")
    return cal


def centre_settings(cal: HeightCalibration) -> CentreSettings:
    """The centre extraction the calibration was made with."""
    return CentreSettings(**cal.centres.model_dump())


def height_model(cal: HeightCalibration, which: str | None = None
                 ) -> tuple[CameraModel, HeightModel]:
    """The camera the calibration was fitted through and the model to measure with
    (``which``: a key of :data:`HEIGHT_MODELS`, None: the file's ``model``), read from the
    file's field of that name."""
    which = which or cal.model
    if which not in HEIGHT_MODELS:
        raise ConfigError(f"height model {which!r}: expected {one_of(HEIGHT_MODELS)}")
    kind, spec = HEIGHT_MODELS[which], getattr(cal, which, None)
    if spec is None:
        raise MeasurementError(f"this height calibration has no {which} model ({kind.absent})")
    return camera_model(cal.camera), kind.model.from_dict(spec.model_dump())


def scan_camera(camera: CameraModel, cal: HeightCalibration | None) -> CameraModel:
    """The camera a scan's points were measured through: the height calibration's (Method
    2), else the rig's ``camera`` (Method 1)."""
    return camera_model(cal.camera) if cal is not None else camera


def crossed_model(cal: HeightCalibration) -> TurnedSheetModel:
    """The calibration's model of the crossed lines; MeasurementError naming its file (or the
    folder it was fitted from) when its recording had lines along y only."""
    if cal.sheet_cross is None:
        where = cal.path or (cal.inputs[0] if cal.inputs else "the height calibration")
        raise MeasurementError(
            f"{where}: this height calibration has no crossed lines (sheet_cross), so it "
            "cannot scan crossed: record the height calibration with crossed lines (the "
            "default of 'insitu record height-calibration') and calibrate again, or scan "
            "without the crossed pass")
    return TurnedSheetModel.from_dict(cal.sheet_cross.model_dump())


def check_same_camera(cal: HeightCalibration, width: int, height: int, where: str) -> None:
    if (cal.camera.width, cal.camera.height) != (width, height):
        raise MeasurementError(
            f"{where}: the camera is {width}×{height} px but the height calibration "
            f"({cal.inputs[0] if cal.inputs else 'file'}) was made with a "
            f"{cal.camera.width}×{cal.camera.height} px camera: another rig")
