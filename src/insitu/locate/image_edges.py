"""The last step of locating a part when a room-light frame is at hand: x, y and the turn
from the top's edges as the camera sees them whole.

A scan line crosses an edge once per line spacing and its end is known along the line to
about 0.07 mm (the pixel, the speckle): a 16 mm insert's turn only to 0.05–0.08°. In a frame
under the room light (laser off) the same edges are seen at every pixel along them: where a
top meets the wall below it or the surface beyond, the grey value steps, and the step's
centre is found to a fraction of a pixel. Each point of the reference's outline (the upper
side of every drop, :func:`outline`) is projected through the camera at the located pose;
along the edge's normal in the image the steepest step of grey within ``SEARCH_PX`` is the
edge, placed by a parabola through the derivative's peak; that pixel's ray cut at the
point's height gives the edge in x, y. Gauss–Newton on the distances across the edges
(Huber weights) turns and shifts the outline onto them, searching again at each step.
Outline points are not used where the part hides them from the camera (a higher wall in
front), where the camera sees their wall as a thin sliver (its grey blends into the step),
where the grey value does not step (two surfaces alike) or a pixel on the way is clipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from insitu.geometry.camera import CameraModel
from insitu.geometry.pose import rot_z
from insitu.locate.edge_align import edge_distance
from insitu.locate.height_image import HeightImage, sample
from insitu.locate.uncertainty import (
    FRAME_BIAS_PX,
    FRAME_TILT_PX,
    LOCK_PX,
    FitTerms,
    covariance,
    frame_tilt,
)

STEEP = 1.0
"""Slope (of the height image blurred as for its normals) above which a pixel lies on an
edge."""
START_MM = 0.5
INSIDE_MM = 0.2
SLOPE_MM = 0.3
"""The top's height at its edge: from ``INSIDE_MM`` inside it (past the edge's own pixels of
the height image), and its slope over this further in."""
SPACING_MM = 0.05
SEARCH_PX = 4.0
STEP_PX = 0.25
SMOOTH_PX = 0.7
"""The frame is blurred this much (Gaussian σ) before the grey values are read: the noise."""
ALONG_PX = np.arange(-2.0, 2.5)
"""Each edge's profile is the mean of profiles this far beside it along the edge, px: the
noise of a frame (a few DN a pixel: another renderer's frame scatters the steps found 0.1 mm
about the edge read from one profile, 0.07 from five)."""


@dataclass(frozen=True)
class Frame:
    """A room-light frame ready to be read between pixels: ``coef`` (H, W) the cubic spline
    coefficients of the frame blurred by ``SMOOTH_PX`` (read along an edge's normal, a
    bilinear frame's slope is constant between pixel centres and pins an edge's step to the
    pixel grid: up to half a pixel along an edge a tenth of a degree off a row), ``clipped``
    (H, W), 1 where the frame is at full scale."""

    coef: np.ndarray
    clipped: np.ndarray


def frame_of(image: np.ndarray) -> Frame:
    """:class:`Frame` of ``image`` (H, W) grey, integer or float."""
    grey = cv2.GaussianBlur(np.asarray(image, np.float32), (0, 0), SMOOTH_PX)
    full = np.iinfo(image.dtype).max if np.issubdtype(image.dtype, np.integer) else np.inf
    return Frame(ndimage.spline_filter(grey.astype(np.float64), 3, mode="nearest"),
                 (np.asarray(image) >= full).astype(np.float32))
CONTRAST = 2.5
"""An edge's step: its slope of grey this many times the median slope along the outline's
profiles (what noise and the surfaces' texture give off the edges)."""
WALL_PX = 3.0
SHOULDER_SLOPE = 0.7
SHOULDER = 6.0
"""A top falling toward its edge steeper than 35° (:func:`shoulder`): its step's bias 1σ is
this many times ``FRAME_BIAS_PX``."""
MAX_SPREAD_MM = 0.1
"""Edges found scattered more than this (robust 1σ) about the fitted outline are not the
part's (its own: 0.01–0.06 mm; the texture of an empty table: 0.45)."""
MIN_POINTS = 50
MIN_FOUND = 0.5
ITERATIONS = 10
SETTLE_MM = 0.005
SETTLE_RAD = np.radians(0.02)
"""Steps at most; the edges found may flicker between pixels (an edge along the pixel grid),
so the last step need only be within the fit's own 1σ or these."""


@dataclass(frozen=True)
class Outline:
    """The part's edges seen from above: ``points`` (K, 3) part frame, mm, on the upper side
    of each drop (z: the top's height there), ``normals`` (K, 2) outward unit, ``below``
    (K,) the height of the surface beyond the drop, mm; ``sigma_mm`` (K,) 1σ of each
    point's edge across it, mm, and ``tilt_mm`` (K,) of its edge's turn, ± at its ends (a
    fitted scan reference's pieces: :mod:`insitu.locate.outline_fit`; None: one for all,
    the reference's)."""

    points: np.ndarray
    normals: np.ndarray
    below: np.ndarray
    sigma_mm: np.ndarray | None = None
    tilt_mm: np.ndarray | None = None


def outline(heights: HeightImage) -> Outline:
    """The edges of the reference's height image, a point every ``SPACING_MM`` along them:
    from every pixel steeper than ``STEEP``, ``START_MM`` inside (beyond the blurred slope and
    the edge's own pixels), out along its normal to where the height falls halfway to the
    lower side (as the edge step finds the reference's edge for a scan line; corners, where
    the edge does not run on straight, are left out); its height: the top's, carried on at
    its slope (from ``SLOPE_MM`` inside) to the edge."""
    gx, gy = heights.slope
    rows, cols = np.nonzero(np.hypot(gx, gy) > STEEP)
    g = -np.column_stack([gx[rows, cols], gy[rows, cols]])
    n = g / np.linalg.norm(g, axis=1, keepdims=True)
    start = np.column_stack([heights.x0_mm + cols * heights.px_mm,
                             heights.y0_mm + rows * heights.px_mm]) - START_MM * n
    z = sample([heights.z], *heights.pixel(start))[0]
    s, normal = edge_distance(heights, np.column_stack([start, z]), n)
    ok = np.isfinite(s)
    edge, n = start[ok] + s[ok, None] * n[ok], n[ok]
    top, below = edge_heights(heights, edge, n)
    _, keep = np.unique(np.floor(edge / SPACING_MM).astype(np.int64), axis=0,
                        return_index=True)
    return Outline(np.column_stack([edge, top])[keep], normal[ok][keep], below[keep])


def edge_heights(heights: HeightImage, edge: np.ndarray, n: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(the top's height at each edge point ``edge`` (K, 2) — from ``INSIDE_MM`` inside along
    its outward normal ``n`` (K, 2), carried on at its slope to the edge —, the height
    ``START_MM`` beyond it) (K,) each, mm."""
    near, far, below = sample([heights.z], *heights.pixel(np.concatenate(
        [edge - INSIDE_MM * n, edge - (INSIDE_MM + SLOPE_MM) * n, edge + START_MM * n])))[0] \
        .reshape(3, -1)
    return near + (near - far) * INSIDE_MM / SLOPE_MM, below


@dataclass(frozen=True)
class ImageFit:
    """The pose from the frame's edges: ``angle_rad`` and ``xy_mm`` (2,) of the part frame's
    origin in the world; ``edges``: outline points whose edge was found and used, of
    ``visible``; ``cov`` (3, 3): the covariance of the turn (rad, about the origin) and the
    shift (mm, world) (:func:`insitu.locate.uncertainty.covariance`: segments of an edge
    vary together, each edge's grey step may be off by ``bias_px``); ``sigma_mm``,
    ``sigma_deg``: 1σ of the shift (its worst direction) and of the turn; ``rms_mm`` the
    distances' robust spread about the fit; ``note``: what held its turn back (a side along
    the pixel rows, :func:`grid_note`; "": nothing)."""

    angle_rad: float
    xy_mm: np.ndarray
    edges: int
    visible: int
    sigma_mm: float
    sigma_deg: float
    rms_mm: float
    cov: np.ndarray | None = None
    terms: FitTerms | None = None
    note: str = ""


def align_image(image: np.ndarray | Frame, camera: CameraModel, heights: HeightImage,
                edges: Outline, T_world_part: np.ndarray,
                max_spread_mm: float = MAX_SPREAD_MM,
                bias_px: float = FRAME_BIAS_PX, search_px: float = SEARCH_PX,
                reference_mm: float = 0.0, near_mm: float = 0.0) -> ImageFit | str:
    """The pose that puts ``edges`` (the reference's, :func:`outline`; ``heights`` its height
    image) on the edges of ``image`` (H, W) grey (or its :func:`frame_of`), a frame of ``camera``
    under the room light with the part as the scan found it, starting from ``T_world_part`` (4, 4; a
    turn about z and a shift). Why not, as a sentence, when the frame is not the camera's, too few
    outline points are in view or show an edge, the edges found scatter about the fit, or the fit
    does not settle (``max_spread_mm``: at most this robust 1σ about the fit). ``search_px``: how
    far from the outline's image each edge is looked for; ``reference_mm``: 1σ of the outline's own
    edges, for the covariance (``edges.sigma_mm`` where given); ``near_mm``: a fit that only brings
    the outline near its edges (a start for a narrower search) stops once a step moves it less than
    this (and turns it less than this over 50 mm)."""
    frame = image if isinstance(image, Frame) else None
    shape = frame.coef.shape if frame is not None else image.shape[:2]
    if shape != (camera.height, camera.width):
        return (f"the frame is {shape[1]}×{shape[0]} px, the camera "
                f"{camera.width}×{camera.height}")
    frame = frame if frame is not None else frame_of(image)
    angle = float(np.arctan2(T_world_part[1, 0], T_world_part[0, 0]))
    t = np.array(T_world_part[:3, 3], np.float64)     # a copy: the caller's pose stays
    width = wall_px(edges, camera, angle, t)
    seen = visible(heights, edges, camera, angle, t) & ~((width > 0) & (width < WALL_PX))
    if seen.sum() < MIN_POINTS:
        return f"{seen.sum()} of the outline's {len(edges.points)} points in view"
    p, n = edges.points[seen], edges.normals[seen]
    reach = np.where(width[seen] > 0, width[seen] / 2, np.inf)
    offs = np.arange(-search_px, search_px + 1e-9, STEP_PX)
    own = None if edges.sigma_mm is None else edges.sigma_mm[seen]
    for _ in range(ITERATIONS):
        R = rot_z(angle)[:2, :2]
        pw = np.column_stack([p[:, :2] @ R.T + t[:2], p[:, 2] + t[2]])
        nw = n @ R.T
        found, e, px_mm = edge_points(frame, camera, pw, nw, offs, reach)
        if found.sum() < max(MIN_POINTS, MIN_FOUND * len(p)):
            return (f"{found.sum()} of the {len(p)} outline points in view show an edge in "
                    f"the frame (at least {max(MIN_POINTS, int(MIN_FOUND * len(p)))} needed)")
        r = np.einsum("ij,ij->i", e - pw[:, :2], nw)[found]
        lever = pw[found, :2] - t[:2]
        J = np.column_stack([nw[found, 1] * lever[:, 0] - nw[found, 0] * lever[:, 1],
                             nw[found]])
        dev = np.abs(r - np.median(r))
        mad = 1.4826 * float(np.median(dev))
        w = np.minimum(1.0, 1.5 * max(mad, 1e-4) / np.maximum(dev, 1e-12))
        if own is not None:                 # the reference's less sure pieces count less
            w = w / (1.0 + (own[found] / max(mad, 0.01)) ** 2)
        A = J.T @ (J * w[:, None])
        try:
            x = np.linalg.solve(A, J.T @ (w * r))
        except np.linalg.LinAlgError:
            return "the frame's edges do not hold the turn and the shift"
        t[:2] += x[1:]
        angle += x[0]
        if (abs(x[0]) < max(2e-5, near_mm / 50)                  # 0.001°, 0.001 mm
                and np.linalg.norm(x[1:]) < max(1e-3, near_mm)):
            break
    if mad > max_spread_mm:
        return (f"the frame's edges scatter {mad:.3f} mm about the outline (at most "
                f"{max_spread_mm:g}): not the part's edges")
    uv = camera.project(np.column_stack([e[found], p[found, 2] + t[2]]))
    steep = shoulder(heights, p[found], n[found]) * px_mm[found]
    terms = FitTerms(J, w, r, p[found, :2], n[found], p[found, 2], steep, mad,
                     frame_tilt(p[found, :2], n[found], p[found, 2], uv),
                     None if own is None else own[found],
                     None if edges.tilt_mm is None else edges.tilt_mm[seen][found])
    cov = covariance(terms, bias_px, reference_mm=reference_mm)
    if (abs(x[0]) > max(np.sqrt(cov[0, 0]), SETTLE_RAD, near_mm / 50)
            or np.linalg.norm(x[1:]) > max(np.sqrt(np.trace(cov[1:, 1:])), SETTLE_MM, near_mm)):
        return (f"the fit to the frame's edges did not settle in {ITERATIONS} steps (the last "
                f"{np.degrees(x[0]):+.4f}°, {np.linalg.norm(x[1:]):.4f} mm)")
    return ImageFit(angle, t[:2].copy(), int(found.sum()), len(p),
                    float(np.sqrt(np.linalg.eigvalsh(cov[1:, 1:]).max())),
                    float(np.degrees(np.sqrt(cov[0, 0]))), mad, cov, terms,
                    grid_note(terms.tilt))


def shoulder(heights: HeightImage, p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(K,) how many times ``FRAME_BIAS_PX`` the grey step of each outline point ``p`` (K, 3)
    (outward normals ``n`` (K, 2)) may lie off as a whole: ``SHOULDER`` where the top falls
    toward the edge steeper than ``SHOULDER_SLOPE`` (it meets its wall at a shallow angle, the
    two alike in grey: the 8.5 mm crowned arc's 46° shoulders read 0.17–0.30 px outward on this
    simulator, 0.65 px on another renderer), else 1."""
    near, far = sample([heights.z], *heights.pixel(np.concatenate(
        [p[:, :2] - INSIDE_MM * n, p[:, :2] - (INSIDE_MM + SLOPE_MM) * n])))[0].reshape(2, -1)
    return np.where((far - near) / SLOPE_MM > SHOULDER_SLOPE, SHOULDER, 1.0)


def grid_note(tilt: np.ndarray) -> str:
    """What holds a frame's turn back when a side of the part runs along the pixel rows or
    columns (its tilt ``tilt`` (K,) px of :func:`insitu.locate.uncertainty.frame_tilt` more
    than twice the light's), as a sentence; "" otherwise."""
    worst = float(tilt.max(initial=0.0))
    if worst <= 2 * FRAME_TILT_PX:
        return ""
    rows = LOCK_PX / np.sqrt(worst ** 2 - FRAME_TILT_PX ** 2)
    within = "one pixel row" if rows < 1.05 else f"{rows:.1f} pixel rows"
    return (f"a side of the part runs within {within} of the camera end to end, "
            "its grey step pulled toward the pixel grid (its turn held to "
            f"± {worst:.2f} px): the part turned a few degrees is held better")


def edge_points(frame: Frame, camera: CameraModel, pw: np.ndarray, nw: np.ndarray,
                offs: np.ndarray, reach: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(found (K,) bool, the edge in x, y (K, 2) world, mm, mm a pixel across the edge
    (K,)) for outline points ``pw`` (K, 3) world with normals ``nw`` (K, 2): along the
    normal's image, within the offsets ``offs`` px (outward at most ``reach`` (K,) px: short
    of the foot of a wall the camera sees, whose step beyond the top's may be the steeper),
    the steepest grey step of ``frame`` (its slope above ``CONTRAST`` times the median), cut
    at the point's height; none where a pixel on the way is at full scale (a step cut off
    there has its steepest slope moved toward the dark side)."""
    uv = camera.project(pw)
    step = camera.project(np.column_stack([pw[:, :2] + 0.05 * nw, pw[:, 2]])) - uv
    d = step / np.maximum(np.linalg.norm(step, axis=1, keepdims=True), 1e-12)
    q = uv[:, None, :] + offs[None, :, None] * d[:, None, :]
    inside = (camera.in_image(q.reshape(-1, 2), 1.0).reshape(len(pw), -1).all(1)
              & np.isfinite(uv).all(1))
    tw = camera.project(np.column_stack([pw[:, :2] + 0.05 * nw[:, ::-1] * [-1, 1], pw[:, 2]]))
    tw = (tw - uv) / np.maximum(np.linalg.norm(tw - uv, axis=1, keepdims=True), 1e-12)
    beside = q[:, None] + ALONG_PX[None, :, None, None] * tw[:, None, None, :]
    prof = ndimage.map_coordinates(frame.coef, [beside[..., 1].ravel(), beside[..., 0].ravel()],
                                   order=3, mode="nearest", prefilter=False
                                   ).reshape(len(pw), len(ALONG_PX), -1).mean(axis=1)
    cut = sample([frame.clipped], q[..., 0].ravel(), q[..., 1].ravel())[0].reshape(len(pw), -1)
    slope = np.abs(np.gradient(prof, STEP_PX, axis=1))
    noise = float(np.median(slope))           # the slope off the edges: noise, texture
    if reach is not None:
        slope = np.where(offs[None, :] <= reach[:, None], slope, 0.0)
    j = np.argmax(slope, axis=1)
    k = np.arange(len(pw))
    peak = (j > 0) & (j < len(offs) - 1) & (slope[k, j] > CONTRAST * max(noise, 1e-3))
    j = np.clip(j, 1, len(offs) - 2)
    y0, y1, y2 = slope[k, j - 1], slope[k, j], slope[k, j + 1]
    den = y0 - 2 * y1 + y2
    frac = np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0)
    px = uv + (offs[j] + frac * STEP_PX)[:, None] * d
    o, dirs = camera.rays(np.nan_to_num(px))
    e = o[:2] + dirs[:, :2] * ((pw[:, 2] - o[2]) / dirs[:, 2])[:, None]
    px_mm = 0.05 / np.maximum(np.linalg.norm(step, axis=1), 1e-12)
    return inside & peak & ~(cut > 0).any(axis=1), e, px_mm


def sliver(edges: Outline, camera: CameraModel, angle: float, t: np.ndarray) -> np.ndarray:
    """(K,) bool: the outline points whose wall the camera sees as a sliver less than
    ``WALL_PX`` wide (turned nearly edge-on to it): its grey blends into the edge's step and
    moves it outward (0.12 px on the insert's side 7° from edge-on). A wall seen wider has
    its own step beyond the top's (:func:`wall_px`); one facing away is hidden behind the
    top."""
    width = wall_px(edges, camera, angle, t)
    return (width > 0) & (width < WALL_PX)


def wall_px(edges: Outline, camera: CameraModel, angle: float, t: np.ndarray) -> np.ndarray:
    """(K,) how wide, px, the camera sees the wall below each outline point, outward across
    its edge (≤ 0: hidden behind the top) at the pose (turn ``angle`` rad, shift ``t``)."""
    R = rot_z(angle)[:2, :2]
    xy, nw = edges.points[:, :2] @ R.T + t[:2], edges.normals @ R.T
    top = camera.project(np.column_stack([xy, edges.points[:, 2] + t[2]]))
    foot = camera.project(np.column_stack([xy, edges.below + t[2]]))
    out = camera.project(np.column_stack([xy + 0.05 * nw, edges.points[:, 2] + t[2]])) - top
    return np.einsum("ij,ij->i", foot - top, out / np.linalg.norm(out, axis=1, keepdims=True))


def visible(heights: HeightImage, edges: Outline, camera: CameraModel, angle: float,
             t: np.ndarray) -> np.ndarray:
    """(K,) bool: the outline points the part does not hide from ``camera`` at the pose
    (turn ``angle`` rad, shift ``t`` (3,)): the height image lies below the ray from each
    point to the camera, looked at every 0.2 mm (in x, y) up to 40 mm or to where every
    ray has risen above the highest height (nothing further can hide a point)."""
    R = rot_z(angle)
    c = R.T @ (camera.centre_world - t)              # the camera in the part's frame
    d = c - edges.points
    d /= np.linalg.norm(d[:, :2], axis=1, keepdims=True)   # per mm in x, y
    h = np.arange(0.2, 40.0, 0.2)
    if (d[:, 2] > 0).all():
        reach = (float(heights.z.max()) - 0.05 - edges.points[:, 2]) / d[:, 2]
        h = h[: int(np.searchsorted(h, reach.max(), side="right")) + 1]
    q = edges.points[:, None, :] + h[None, :, None] * d[:, None, :]
    z = sample([heights.z], *heights.pixel(q.reshape(-1, 3)))[0].reshape(q.shape[:2])
    return ~(z > q[..., 2] + 0.05).any(axis=1)
