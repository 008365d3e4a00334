"""Field calibration use cases: measure where the spots (or marked circles) of a recorded field
calibration landed, fit the correction, correct targets, check for drift.

A spot's landing point: the camera ray of its centre (the sequence's camera, i.e. the
operator's calibration) meets the plate z = plate_z_mm; a plate not at z = 0 is carried to
z = 0 along the nominal beam (through the pivot, or vertical for a telecentric lens). Marked
circles (Mikkelstrup et al. §2.4): see :mod:`insitu.calibrate.fiducials`.
"""

from __future__ import annotations

import csv
import io
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from insitu.calibrate.fiducials import CircleSettings, find_circles
from insitu.calibrate.field import DEFAULT_GOALS, DEFAULT_SMOOTHING, MIN_POINTS, Selection
from insitu.calibrate.field_areas import area_table, stats
from insitu.calibrate.field_file import FIELD_METHODS, AreaRow, CVRow, FieldCorrection
from insitu.calibrate.report import report_image, write_report_png
from insitu.errors import CalibrationError, FormatError
from insitu.formats.atomic import atomic_write_text
from insitu.formats.limits import MAX_JSON_BYTES, read_limited
from insitu.formats.sequence import Sequence
from insitu.formats.validation import one_of
from insitu.services.common import Progress, camera_model, save_with_picture
from insitu.vision.spots import SpotSettings, find_spot

MAX_FAILED_FRACTION = 0.1


@dataclass
class SpotMeasurements:
    """Spots of a field-calibration sequence: frame indices (N,), commands Q (N, 2) mm, spot
    centres (N, 2) px, landing points P on z = 0 (N, 2) mm; ``skipped``: (frame, reason)
    of the frames without a usable spot; ``out_of_view``: how many of those were outside
    the camera's view."""

    frames: np.ndarray
    commands: np.ndarray
    pixels: np.ndarray
    landed: np.ndarray
    plate_z_mm: float
    skipped: list[tuple[int, str]] = field(default_factory=list)
    out_of_view: int = 0

    @property
    def deviations(self) -> np.ndarray:
        """δ = P − Q, (N, 2) mm."""
        return self.landed - self.commands


def _plate_height(seq: Sequence) -> float:
    zs = [f.plate_z_mm for f in seq.frames]
    for i, z in enumerate(zs):
        if abs(z - zs[0]) > 1e-6:
            raise CalibrationError(
                f"{seq.folder}: frames[{i}].plate_z_mm: {z:g} differs from frames[0]."
                f"plate_z_mm = {zs[0]:g}: a field calibration takes the plate at one height "
                "(record one sequence per height)")
    return float(zs[0])


def _spot_pixels(seq: Sequence, settings: SpotSettings, progress: Progress | None):
    """Per frame: the spot centre (2,) px, or why there is none (frames are read and searched
    on a few threads)."""
    def one(i: int):
        try:
            return find_spot(seq.read_frame(i), settings, f"{seq.folder / seq.frames[i].file}").uv
        except CalibrationError as e:
            return str(e)

    results = []
    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        for k, r in enumerate(pool.map(one, range(len(seq)))):
            results.append(r)
            if progress:
                progress(k + 1, len(seq))
    return results


def _circle_centres(seq: Sequence, cam, z: float, settings: CircleSettings,
                    progress: Progress | None):
    """Marked-fiducial frames: per circle its frame, command (2,) mm and centre on the plate
    (2,) mm or why there is none."""
    frames, Q, found = [], [], []
    for i, f in enumerate(seq.frames):
        if f.fiducials is None:
            raise CalibrationError(f"{seq.folder}: frames[{i}]: a spot frame among marked-"
                                   "circle frames (record one kind per sequence)")
        q = np.asarray(f.fiducials, np.float64)
        c, why = find_circles(seq.read_frame(i), cam, z, q, f.fiducial_diameter_mm, settings)
        where = f"{seq.folder / f.file}"
        found += [c[j] if r is None else f"{where}: circle at {q[j].tolist()}: {r}"
                  for j, r in enumerate(why)]
        frames += [i] * len(q)
        Q.append(q)
        if progress:
            progress(i + 1, len(seq))
    return np.array(frames, int), np.vstack(Q), found


def measure_spots(seq: Sequence, settings: SpotSettings = SpotSettings(),
                  progress: Progress | None = None, max_deviation_mm: float = 10.0,
                  strict: bool = True, circles: CircleSettings = CircleSettings()
                  ) -> SpotMeasurements:
    """Where the head's spots landed: in spot frames (``spot``) the pilot spot's centre, in
    marked-fiducial frames (``fiducials``: the commanded centres of circles marked on the
    plate, ``fiducial_diameter_mm``) each circle's fitted centre; each intersected with the
    plate through the camera. Spots outside the camera's view, not found, or more than
    ``max_deviation_mm`` from their command are skipped; with ``strict``, CalibrationError if
    more than 10 % of those in view fail or fewer than 10 remain."""
    if seq.kind != "field-calibration":
        raise CalibrationError(f"{seq.folder}: a '{seq.kind}' sequence, not a field calibration")
    z = _plate_height(seq)
    cam, head = camera_model(seq.camera), seq.scan_head
    H, tele = head.pivot_height_mm, head.lens == "telecentric"
    scale = 1.0 if tele else (H - z) / H                  # z = 0 → plate, along the beam
    marked = any(f.spot is None for f in seq.frames)
    if marked:
        frames, Q, found = _circle_centres(seq, cam, z, circles, progress)
        Q_plate = Q * scale
    else:
        frames = np.arange(len(seq))
        Q = np.array([f.spot for f in seq.frames], np.float64)
        Q_plate = Q * scale
        found = _spot_pixels(seq, settings, progress)
    expected = cam.project(np.column_stack([Q_plate, np.full(len(Q), z)]))
    in_view = cam.in_image(np.nan_to_num(expected, nan=-1e9))
    ok = np.array([not isinstance(r, str) for r in found], bool)
    on_plate = np.full_like(Q, np.nan)
    uv = np.full_like(Q, np.nan)
    if ok.any():
        got = np.array([r for r in found if not isinstance(r, str)], np.float64)
        if marked:
            on_plate[ok] = got
            uv[ok] = cam.project(np.column_stack([got, np.full(len(got), z)]))
        else:
            uv[ok] = got
            o, d = cam.rays(got)
            s = (z - o[2]) / d[:, 2]
            on_plate[ok] = o[:2] + s[:, None] * d[:, :2]
    landed = on_plate / scale
    far = ok & (np.linalg.norm(landed - Q, axis=1) > max_deviation_mm)
    what = "circle" if marked else "spot"
    skipped = []
    for i in np.nonzero(~ok | far)[0]:
        reason = found[i] if not ok[i] else (
            f"{seq.folder / seq.frames[frames[i]].file}: the {what} is "
            f"{np.linalg.norm(landed[i] - Q[i]):.1f} mm from its command (more than "
            f"{max_deviation_mm:g} mm: a reflection?)")
        skipped.append((int(frames[i]), reason if in_view[i] else "outside the camera's view"))
    good = ok & ~far
    m = SpotMeasurements(frames[good], Q[good], uv[good], landed[good], z, skipped,
                         int(np.sum(~good & ~in_view)))
    if strict:
        failed = [r for (_, r), i in zip(skipped, np.nonzero(~good)[0]) if in_view[i]]
        if len(failed) > MAX_FAILED_FRACTION * max(int(in_view.sum()), 1):
            raise CalibrationError(f"{seq.folder}: no usable {what} in {len(failed)} of "
                                   f"{int(in_view.sum())} {what + 's' if marked else 'frames'} "
                                   f"in the camera's view, e.g. {failed[0]}")
        if good.sum() < MIN_POINTS:
            first = f": {skipped[0][1]}" if skipped else ""
            raise CalibrationError(f"{seq.folder}: only {int(good.sum())} {what}s measured (need "
                                   f"at least {MIN_POINTS} for a field correction){first}")
    return m


def calibrate_field(folder: str | Path, method: str = "rbf",
                    settings: SpotSettings = SpotSettings(), progress: Progress | None = None,
                    sigmas: list[float] | None = None, goals=DEFAULT_GOALS,
                    smoothing=DEFAULT_SMOOTHING) -> FieldCorrection:
    """Measure the spots of a recorded field-calibration folder and fit the correction
    (``method``: a key of :data:`FIELD_METHODS`), σ / goal / smoothing chosen by 5-fold CV."""
    if method not in FIELD_METHODS:
        raise CalibrationError(f"method {method!r}: expected {one_of(FIELD_METHODS)}")
    seq = Sequence.open(folder)
    m = measure_spots(seq, settings, progress)
    Q, D = m.commands, m.deviations
    half = np.asarray(seq.scan_head.field_size_mm) / 2
    fm = FIELD_METHODS[method]
    sel: Selection = fm.select(Q, D, (-half[0], half[0], -half[1], half[1]), sigmas=sigmas,
                               goals=goals, smoothing=smoothing)
    spec = fm.spec.of(sel.model, **sel.cv.params)
    fit = D - sel.model(Q)
    after = -sel.cv.residuals                      # landing error expected after correction
    region = [float(Q[:, 0].min()), float(Q[:, 0].max()), float(Q[:, 1].min()),
              float(Q[:, 1].max())]
    span = 0.5 * max(region[1] - region[0], region[3] - region[2])
    before_s, fit_s, cv_s = stats(D), stats(fit), stats(after)
    residuals = {"points": float(len(Q)), "spots_skipped": float(len(m.skipped)),
                 "before_rms_mm": before_s.rms_mm[2], "before_max_mm": before_s.max_mm[2],
                 "fit_rms_mm": fit_s.rms_mm[2], "fit_max_mm": fit_s.max_mm[2],
                 "cv_rms_mm": cv_s.rms_mm[2], "cv_max_mm": cv_s.max_mm[2],
                 "cv_fold_rms_mean_mm": sel.cv.mean_fold_rms,
                 "cv_fold_rms_std_mm": sel.cv.std_fold_rms}
    residuals.update(spec.counts())
    notes = (f"{len(seq)} frames, {len(Q)} spots measured"
             + (f", {len(m.skipped)} skipped ({m.out_of_view} outside the camera's view)"
                if m.skipped else "")
             + f"; plate at z = {m.plate_z_mm:g} mm; {spec.summary()}; 'after' = 5-fold CV "
               "prediction error at the measured points")
    return FieldCorrection(
        method=method, field_size_mm=list(seq.scan_head.field_size_mm), region_mm=region,
        plate_z_mm=m.plate_z_mm, camera=seq.camera, **{method: spec},
        cross_validation=[CVRow(params={k: float(v) for k, v in c.params.items()},
                                rms_mm=c.rms, fold_rms_mm=c.fold_rms.tolist())
                          for c in sel.tried],
        areas_before=[AreaRow.of(s) for s in area_table(Q, D, span)],
        areas_after=[AreaRow.of(s) for s in area_table(Q, after, span)],
        commands_mm=Q.tolist(), landed_mm=m.landed.tolist(), after_mm=after.tolist(),
        inputs=[str(Path(folder))],
        residuals=residuals, notes=notes)


def report_png(correction: FieldCorrection, path: str | Path) -> None:
    """The quiver report of a correction (before / after at the measured points, Table 1)."""
    Q, P = np.array(correction.commands_mm), np.array(correction.landed_mm)
    if not len(Q):
        raise CalibrationError("this field correction holds no measurements to report")
    D = P - Q
    if len(correction.after_mm) == len(Q):
        after, label = np.array(correction.after_mm), "after (5-fold CV)"
    else:
        after, label = D - correction.delta()(Q), "after (fit)"
    half = max(np.abs(Q).max(), 1e-3) * 1.08
    write_report_png(path, report_image(Q, D, after, half, correction.areas_before,
                                        correction.areas_after, title=correction.notes,
                                        after_label=label))


# -- targets and commands ------------------------------------------------------------------
def read_targets_csv(path: str | Path) -> np.ndarray:
    """(N, 2) targets, mm, from a CSV with header ``x,y``. FormatError naming file and line."""
    path = Path(path)
    raw = read_limited(path, MAX_JSON_BYTES, "targets CSV", missing="file not found")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise FormatError(f"{path}: cannot read (not UTF-8 text at byte {e.start})") from None
    rows = [r for r in csv.reader(io.StringIO(text))]
    if not rows or [c.strip().lower() for c in rows[0]] != ["x", "y"]:
        raise FormatError(f"{path}: line 1: expected the header 'x,y', got "
                          f"{','.join(rows[0]) if rows else 'an empty file'!r}")
    out = []
    for n, r in enumerate(rows[1:], start=2):
        if not r or all(not c.strip() for c in r):
            continue
        try:
            if len(r) != 2:
                raise ValueError
            x, y = float(r[0]), float(r[1])
            if not (np.isfinite(x) and np.isfinite(y)):
                raise ValueError
        except ValueError:
            raise FormatError(f"{path}: line {n}: expected two finite numbers x,y (mm), got "
                              f"{','.join(r)!r}") from None
        out.append((x, y))
    if not out:
        raise FormatError(f"{path}: no targets (expected rows x,y after the header)")
    return np.array(out, np.float64)


def write_commands_csv(path: str | Path, commands: np.ndarray) -> None:
    """Header ``x,y``, one command per row (mm, 6 decimals), written atomically."""
    lines = ["x,y"] + [f"{x:.6f},{y:.6f}" for x, y in np.asarray(commands).reshape(-1, 2)]
    atomic_write_text(path, "\n".join(lines) + "\n")


def correct_targets(correction: FieldCorrection, targets: np.ndarray, where: str = "target"
                    ) -> np.ndarray:
    """Corrected commands (N, 2) for ``targets`` (N, 2), mm (see FieldCorrection.correct)."""
    return correction.correct(targets, where)


# -- drift -------------------------------------------------------------------------------
@dataclass(frozen=True)
class DriftResult:
    """Re-measured spots against the correction: commands (N, 2), measured and predicted
    landing points (N, 2), residuals = measured − predicted (N, 2), mm."""

    commands: np.ndarray
    measured: np.ndarray
    predicted: np.ndarray
    tolerance_mm: float

    @property
    def residuals(self) -> np.ndarray:
        return self.measured - self.predicted

    rms_mm = property(lambda self: float(np.sqrt(np.mean(np.sum(self.residuals**2, 1)))))
    max_mm = property(lambda self: float(np.linalg.norm(self.residuals, axis=1).max()))
    holds = property(lambda self: self.max_mm <= self.tolerance_mm,
                     doc="True if every residual is within the tolerance.")


def check_drift(correction: FieldCorrection, sequence: Sequence | str | Path,
                settings: SpotSettings = SpotSettings(), tolerance_mm: float | None = None,
                progress: Progress | None = None) -> DriftResult:
    """Does the correction still hold? ``sequence``: a field-calibration recording of a few
    spots, commanded anywhere (raw or corrected commands alike): each spot must land where the
    correction predicts, C + δ(C). ``tolerance_mm`` defaults to 3 × the correction's CV RMS
    (at least 0.03 mm)."""
    seq = sequence if isinstance(sequence, Sequence) else Sequence.open(sequence)
    m = measure_spots(seq, settings, progress, strict=False)
    if not len(m.commands):
        raise CalibrationError(f"{seq.folder}: no spot measured, cannot check the drift")
    failed = [r for i, r in m.skipped if r != "outside the camera's view"]
    if failed:
        raise CalibrationError(f"{seq.folder}: {failed[0]}")
    predicted = m.commands + correction.delta()(m.commands)
    if tolerance_mm is None:
        tolerance_mm = max(3.0 * correction.residuals.get("cv_rms_mm", 0.01), 0.03)
    return DriftResult(m.commands, m.landed, predicted, float(tolerance_mm))


def calibrate_and_report(folder: str | Path, out: str | Path, method: str = "rbf",
                         progress: Progress | None = None, **options) -> FieldCorrection:
    """:func:`calibrate_field` (``options``: its sigmas, goals, smoothing), then write ``out``
    (JSON) and the report beside it (.png); nothing is left behind if either fails."""
    correction = calibrate_field(folder, method, progress=progress, **options)
    save_with_picture(out, correction, lambda png: report_png(correction, png))
    return correction
