"""Frames of a line scan in, point cloud out — streaming: one frame at a time, flat memory."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree

from insitu.errors import MeasurementError
from insitu.formats.pointcloud import PointCloud
from insitu.geometry.camera import CameraModel
from insitu.reconstruct.bands import Packing, Sheets, exclusive
from insitu.reconstruct.consistency import cross_line_inliers
from insitu.reconstruct.height_models import HeightModel
from insitu.reconstruct.plane import line_band, line_runs_along_rows, reconstruct_line
from insitu.reconstruct.plate_models import check_bracket
from insitu.reconstruct.turned_sheet import (
    TurnedSheetModel,
    line_angle,
    same_direction,
    turned_offset,
)
from insitu.vision.band_centres import centres_in_bands
from insitu.vision.detect import LineCentres
from insitu.vision.extract import CentreSettings, extract_centres


class ScanReconstructor:
    """Accumulates points frame by frame.

    camera: the calibrated camera (for a height model: the one it was fitted through).
    pivot_height_mm, telecentric: the scan head's nominal geometry (a recorded sequence's
    ``scan_head``, docs/formats.md).
    height_model: None for Method 1 (light plane, Li et al. §2.1; any line direction), else
    Method 2 with that height calibration (Li et al. §2.2, or ours) for lines along y, and
    ``cross_model`` (None: none) for the crossed lines at its angle to x. settings: the
    centre extraction (with a height model: the one it was calibrated with). z_range_mm:
    heights the surface can have (the focus range); the line is only searched where its light
    plane can put it (ghosts and reflections elsewhere are ignored). None: the whole column.
    :meth:`set_ambient` before the frames gives every point the room-light grey value of the
    pixel it was measured at (attribute ``ambient``). pixel_bits: the frames' significant bits
    (a Mono12 camera's: 12; None: their dtype's), which the centres' thresholds are
    fractions of.
    """

    def __init__(self, camera: CameraModel, pivot_height_mm: float, telecentric: bool = False,
                 height_model: HeightModel | None = None,
                 settings: CentreSettings = CentreSettings(),
                 z_range_mm: tuple[float, float] | None = None, min_points: int = 5,
                 cross_model: TurnedSheetModel | None = None, pixel_bits: int | None = None):
        self.camera, self.H, self.telecentric = camera, pivot_height_mm, telecentric
        self.model, self.settings, self.z_range = height_model, settings, z_range_mm
        self.cross_model, self.pixel_bits = cross_model, pixel_bits
        self._angles: dict[int, float] = {}     # line index → its angle to x
        self.min_points = min_points
        self._chunks: list[tuple[np.ndarray, ...]] = []
        self.frames = 0
        self.frames_with_line = 0
        self.outliers_removed = 0
        self.unconfirmed_removed = 0
        self.last_centres = np.zeros((0, 2))
        self.last_points = np.zeros((0, 3))
        self._ambient: np.ndarray | None = None
        self._sheets: Sheets | None = None

    def set_ambient(self, image: np.ndarray | None) -> None:
        """The laser-off frame under the room light, (H, W) uint8 or uint16 as the line
        frames (None: none); each point then gets its grey value, 0..1 of full scale."""
        if image is not None and image.shape != (self.camera.height, self.camera.width):
            raise MeasurementError(
                f"ambient frame: {image.shape[1]}×{image.shape[0]} px, but the camera "
                f"calibration is for {self.camera.width}×{self.camera.height} px")
        self._ambient = image

    @property
    def method(self) -> str:
        return "plane" if self.model is None else f"height ({self.model.name})"

    def add(self, index: int, image: np.ndarray, start, end) -> int:
        """Process frame ``index`` of the line start → end (mm); returns the points it gave.
        ``last_centres`` (M, 2) px and ``last_points`` (K, 3) mm then hold this frame's line
        centres and points (before outlier removal), for live display."""
        self._check(index, image)
        self.frames += 1
        band, upper = None, 0
        if self.z_range:
            rows, lo, hi, upper = line_band(self.camera, start, end, self.H, self.z_range,
                                            telecentric=self.telecentric)
            band = (lo, hi)
        else:
            rows = line_runs_along_rows(self.camera, start, end)
        centres = extract_centres(image, self.settings, band, rows, upper, self.pixel_bits)
        self.last_centres, self.last_points = centres.uv, np.zeros((0, 3))
        return self._store(index, start, end, centres)

    def add_lines(self, image: np.ndarray, lines, ids, z_range: tuple[float, float],
                  packing: Packing = Packing(), excess_light: np.ndarray | None = None) -> int:
        """Process a frame of several ``lines`` ((start, end) mm each) drawn in one exposure,
        line ``ids[k]`` of the scan each (its place across its pass: the cloud's ``line``):
        each line's centres only inside its band for surfaces within ``z_range`` mm
        (:mod:`insitu.reconstruct.bands`, widened by ``packing``), none where two bands hold
        the same pixel. ``excess_light`` (:func:`excess_room_light`): subtracted first
        (:func:`less_room_light`), and each peak must stand the detector's floor above the
        room light's level it keeps, as in a frame of one line. Returns the points the frame gave;
        ``last_centres``, ``last_points`` hold all its lines'."""
        self._check(ids[0], image)
        if excess_light is not None:
            image = less_room_light(image, excess_light,
                                    2 ** self.pixel_bits - 1 if self.pixel_bits else None)
        self.frames += len(lines)
        bands = exclusive([self.sheets.band(a, b, z_range, packing.margin_px) for a, b in lines],
                          packing.guard_px)
        level = excess_light.level if excess_light is not None else 0.0
        found = centres_in_bands(image, bands, self.settings, packing.edge_px, self.pixel_bits,
                                 level)
        total, centres, points = 0, [], []
        for (a, b), k, c in zip(lines, ids, found):
            total += self._store(int(k), a, b, c)
            centres.append(c.uv)
            points.append(self.last_points)
        self.last_centres, self.last_points = np.vstack(centres), np.vstack(points)
        return total

    def twin(self) -> "ScanReconstructor":
        """A new, empty reconstructor that measures as this one does (a survey's)."""
        return ScanReconstructor(self.camera, self.H, self.telecentric, self.model,
                                 self.settings, self.z_range, self.min_points,
                                 self.cross_model, self.pixel_bits)

    def heights(self, radius_mm: float = 1.5, neighbours: int = 8
                ) -> tuple[float, float] | None:
        """The lowest and highest of the points so far, (low, high) mm, less isolated ones
        (:func:`density_inliers`: a speck off the surface widens nothing); None: no points."""
        if not self._chunks:
            return None
        pts = np.concatenate([c[0] for c in self._chunks])
        keep = density_inliers(pts, radius_mm, neighbours)
        if not keep.any():
            return None
        return float(pts[keep, 2].min()), float(pts[keep, 2].max())

    @property
    def sheets(self) -> Sheets:
        """The light sheets the bands follow (the height model's, else the nominal planes)."""
        if self._sheets is None:
            self._sheets = Sheets(self.camera, self.H, self.telecentric, self.model,
                                  self.cross_model)
        return self._sheets

    def _check(self, index: int, image: np.ndarray) -> None:
        if image.shape != (self.camera.height, self.camera.width):
            raise MeasurementError(
                f"frame {index}: {image.shape[1]}×{image.shape[0]} px, but the camera "
                f"calibration is for {self.camera.width}×{self.camera.height} px")

    def _store(self, index: int, start, end, centres: LineCentres) -> int:
        """The points of line ``index`` (start → end, mm) from its ``centres``, kept when
        there are enough; ``last_points`` holds them."""
        self.last_points = np.zeros((0, 3))
        if len(centres) < self.min_points:
            return 0
        if self.model is None:
            pts = reconstruct_line(self.camera, centres.uv, start, end, self.H, self.telecentric)
        else:
            pts = self._height_points(index, start, end, centres.u, centres.v)
        ok = np.isfinite(pts).all(axis=1)
        if ok.sum() < self.min_points:
            return 0
        self.frames_with_line += 1
        self._angles[index] = line_angle(start, end)
        self.last_points = pts[ok]
        chunk = (pts[ok], centres.peak[ok], np.full(ok.sum(), index, np.int32),
                 np.clip(centres.contrast[ok] / centres.full_scale, 0, 1))
        if self._ambient is not None:
            chunk += (grey_at(self._ambient, centres.uv[ok], self.pixel_bits),)
        self._chunks.append(chunk)
        return int(ok.sum())

    def _height_points(self, index: int, start, end, u: np.ndarray, v: np.ndarray
                       ) -> np.ndarray:
        """Method 2: the along-y model for lines along y, the crossed one at its angle."""
        if abs(start[0] - end[0]) <= 1e-9:
            return self.model.points(self.camera, float(start[0]), u, v)
        c = self.cross_model
        if c is not None and same_direction(start, end, c.angle_deg):
            return c.points(self.camera, turned_offset(start, end, c.angle_deg), u, v)
        raise MeasurementError(
            f"frame {index}: the height calibration has lines along y"
            + (f" and at {c.angle_deg:g}° to x" if c is not None else " only")
            + f", got {list(start)} → {list(end)} ({line_angle(start, end):g}° to x)")

    def cloud(self, outlier_radius_mm: float = 1.5, outlier_neighbours: int = 8,
              cross_check: bool = True) -> PointCloud:
        """All points so far, less isolated ones (fewer than ``outlier_neighbours`` others
        within ``outlier_radius_mm``: spurious detections floating off the surface; 0 keeps
        all) and, with ``cross_check``, those the neighbouring lines do not confirm
        (:mod:`insitu.reconstruct.consistency`; counted in ``unconfirmed_removed``), and a few
        strays outside the calibrated heights (:func:`check_bracket`; counted with the
        isolated ones). Raises MeasurementError when no frame showed a line or more heights
        leave the calibrated range."""
        if not self._chunks:
            raise MeasurementError(f"no laser line found in any of {self.frames} frames "
                                   "(laser off, exposure too low, or the part outside the view)")
        pts, *values = (np.concatenate(c) for c in zip(*self._chunks))
        attrs = dict(zip(("intensity", "line", "quality", "ambient"), values))
        keep = (density_inliers(pts, outlier_radius_mm, outlier_neighbours)
                if outlier_neighbours else slice(None))
        pts, attrs = pts[keep], {k: a[keep] for k, a in attrs.items()}
        self.outliers_removed = int(len(keep) - keep.sum()) if isinstance(keep, np.ndarray) else 0
        if cross_check:
            confirmed = self._confirmed(pts, attrs["line"])
            pts, attrs = pts[confirmed], {k: a[confirmed] for k, a in attrs.items()}
            self.unconfirmed_removed = int(len(confirmed) - confirmed.sum())
        if self.model is not None:               # a few strays (a ghost's streak) dropped
            inside = check_bracket(self.model, pts[:, 2], "scan")
            pts, attrs = pts[inside], {k: a[inside] for k, a in attrs.items()}
            self.outliers_removed += int(len(inside) - inside.sum())
        return PointCloud(pts, attrs)

    def _confirmed(self, pts: np.ndarray, line: np.ndarray) -> np.ndarray:
        """(N,) bool: :func:`cross_line_inliers` within each pass (lines of one direction;
        a crossed pass's lines are no neighbours of the other pass's)."""
        keys = np.array(sorted(self._angles))
        angle = np.array([self._angles[k] for k in keys])[np.searchsorted(keys, line)]
        keep = np.ones(len(pts), bool)
        for a in np.unique(angle):
            sel = angle == a
            keep[sel] = cross_line_inliers(pts[sel], line[sel])
        return keep


@dataclass(frozen=True)
class ExcessLight:
    """The room light a frame of K lines holds beyond one line's exposure: ``split`` (2, H, W)
    in the laser-off frame's dtype, what to take from and what to give to the frame (its
    texture and shading), and ``level`` (DN), what it keeps ((K − 1)/K of the laser-off
    frame's median over the pixels read)."""

    split: np.ndarray
    level: float


def excess_room_light(laser_off: np.ndarray, k: int) -> ExcessLight:
    """:class:`ExcessLight`, what to take from and what to give to a frame:
    (K − 1)/K of ``laser_off`` (H, W), a frame with the laser off exposed as long as a frame
    of ``k`` lines, less its median level over the pixels read (> 0; nothing where none was
    read), split by sign: the texture and shading of the room light such a frame holds
    beyond one line's exposure. Applied to the frame (:func:`less_room_light`), it leaves
    the room light's texture of a one-line frame at the level of K exposures. The texture of
    the other K − 1 exposures biases the centres (on the simulator's tilted plane and
    freeform 1.16–1.2 × the RMS of one line a frame at K = 4; the lines' own stray light,
    the bands and the sheets' lookup cost nothing: benchmarks/multiline_why.py). Their level
    stays in the frame and is returned: a peak must stand the detector's absolute floor
    (``min_peak``) above it (:func:`~insitu.vision.band_centres.centres_in_bands`), as in a
    frame of one line (on the level alone, stripes too faint for that floor passed and
    gave the simulator's packed insert its worst points: benchmarks/multiline.py)."""
    read = laser_off > 0
    excess = np.rint(laser_off.astype(np.float64) * ((k - 1) / k))
    level = float(np.median(excess[read])) if read.any() else 0.0
    signed = np.where(read, excess - level, 0.0)
    split = np.stack([np.maximum(signed, 0), np.maximum(-signed, 0)]).astype(laser_off.dtype)
    return ExcessLight(split, level)


def less_room_light(image: np.ndarray, excess: ExcessLight, top: int | None = None
                    ) -> np.ndarray:
    """``image`` (H, W, uint8 or uint16) less ``excess`` (:func:`excess_room_light`): its
    split's first plane taken, its second given, clipped to 0 … ``top`` (the frame's full
    scale; None: the dtype's). Saturating integer steps: a frame's subtraction in ≈ 1 ms
    at 2448 × 2048, where int32 arithmetic takes ≈ 20 × that."""
    out = cv2.add(cv2.subtract(image, excess.split[0]), excess.split[1])
    if top is not None and top < np.iinfo(image.dtype).max:
        np.minimum(out, top, out=out)
    return out


def density_inliers(points: np.ndarray, radius_mm: float, neighbours: int) -> np.ndarray:
    """(N,) bool: points with at least ``neighbours`` others within ``radius_mm`` (a radius
    outlier test, by the distance to the ``neighbours``-th nearest other point). Unlike the
    mean-distance test it keeps the ends of lines and the edges of parts, where a line scan's
    density is lower but real."""
    d, _ = cKDTree(points).query(points, k=neighbours + 1, distance_upper_bound=radius_mm)
    return np.isfinite(d[:, -1])


def grey_at(image: np.ndarray, uv: np.ndarray, bits: int | None = None) -> np.ndarray:
    """(M,) float32 grey values of ``image`` (H, W) uint8 or uint16 at the sub-pixel
    positions ``uv`` (M, 2) px (bilinear; edges clamped), 0..1 of full scale: 2^bits − 1
    (a Mono12 camera's 16-bit PNG holds 0 … 4095), or the dtype's when ``bits`` is None."""
    full = float(2 ** bits - 1) if bits else (255.0 if image.dtype == np.uint8 else 65535.0)
    grey = map_coordinates(image, (uv[:, 1], uv[:, 0]), order=1, mode="nearest",
                           output=np.float32)
    return np.clip(grey / np.float32(full), 0, 1)
