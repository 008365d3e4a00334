"""The room light on what the simulated camera sees: diffuse light from above and, a share of
it, one lamp whose light the parts shadow (the laser-off frames, the lines' background), each
pixel an edge crosses integrated over its area."""

from __future__ import annotations

import cv2
import numpy as np

from insitu.sim.rig import SimRig
from insitu.sim.scene import Scene

EDGE_SUB = 4
"""Rays a side in a pixel an edge crosses (4 × 4)."""


def room_shade(rig: SimRig, scene: Scene, hits, albedo: np.ndarray) -> np.ndarray:
    """(M,) room light, DN at the nominal exposure, on the M surfaces ``hits`` met (normals
    toward the camera) of ``albedo`` (M,): diffuse light from above (0.6 + 0.4·|n_z| of an
    albedo-1 top's ``ambient_dn``) and, its ``lamp_share``, one lamp at ``lamp_deg``
    (azimuth, elevation): Lambert's cosine, scaled to the same level on a flat top, and
    nothing where the scene lies between the point and the lamp (a part's shadow)."""
    o = rig.optics
    pts, nrm = hits.points[hits.hit], hits.normals[hits.hit]
    shade = 0.6 + 0.4 * np.abs(nrm[:, 2])
    if o.lamp_share > 0 and len(pts):
        az, el = np.radians(o.lamp_deg)
        lamp = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        lit = np.maximum(nrm @ lamp, 0.0) / lamp[2]
        on = lit > 0
        lit[on] *= ~scene.cast(pts[on] + 1e-3 * nrm[on], np.tile(lamp, (on.sum(), 1)),
                               lift_to_z=None).hit
        shade = (1.0 - o.lamp_share) * shade + o.lamp_share * lit
    return o.ambient_dn * albedo * shade


def room_light_at(rig: SimRig, scene: Scene, uv: np.ndarray):
    """For pixel positions ``uv`` (N, 2) of ``rig``'s true camera: (room light DN at the
    nominal exposure, part index (−1: none), the normal's |z|, depth along the camera's axis
    mm) (N,) each; the hits and the rays' directions (N, 3)."""
    cam, o = rig.camera, rig.optics
    origin, dirs = cam.rays(uv)
    hits = scene.cast(np.broadcast_to(origin, dirs.shape), dirs)
    pts, part = hits.points[hits.hit], hits.part[hits.hit]
    nz = np.abs(hits.normals[hits.hit, 2])
    fall = 1.0 + o.ambient_gradient * (pts[:, 0] + 0.5 * pts[:, 1]) / 100.0
    out = [np.zeros(len(uv)), np.full(len(uv), -1.0), np.zeros(len(uv)), np.zeros(len(uv))]
    out[0][hits.hit] = room_shade(rig, scene, hits, scene.albedo(pts, part)) * fall
    out[1][hits.hit], out[2][hits.hit] = part, nz
    out[3][hits.hit] = cam.to_camera(pts)[:, 2]
    return out, hits, dirs


def ambient_image(rig: SimRig, scene: Scene, scale: int, blur_px):
    """(H, W) float32 room light on the scene as the camera sees it (textured albedo,
    shading, a fall-off across the field), DN at the nominal exposure, and the hits and
    directions (h·w,) of the cast it comes from: one ray a ``scale`` × ``scale`` block,
    enlarged, except in the pixels a part's edge or a wall crosses, where ``EDGE_SUB`` ×
    ``EDGE_SUB`` rays integrate the pixel's area (an edge falls between pixels as on the
    sensor); then the lens PSF at the scene's depth (``blur_px(depth_mm)``, px)."""
    H, W = rig.camera.height, rig.camera.width
    h, w = (H + scale - 1) // scale, (W + scale - 1) // scale
    u, v = np.meshgrid(np.arange(w) * scale + (scale - 1) / 2,
                       np.arange(h) * scale + (scale - 1) / 2)
    (shade, part_id, nz, depth), hits, dirs = room_light_at(
        rig, scene, np.column_stack([u.ravel(), v.ravel()]))
    img = cv2.resize(shade.reshape(h, w).astype(np.float32), (W, H),
                     interpolation=cv2.INTER_LINEAR)
    edge = edge_pixels(part_id.reshape(h, w), nz.reshape(h, w), depth.reshape(h, w))
    edge = cv2.resize(cv2.dilate(edge.astype(np.uint8), np.ones((3, 3), np.uint8)),
                      (W, H), interpolation=cv2.INTER_NEAREST)
    rows, cols = np.nonzero(edge)
    if len(rows):
        img[rows, cols] = room_light_at(rig, scene, area_rays(rows, cols))[0][0] \
            .reshape(len(rows), -1).mean(1)
    seen = part_id >= 0
    blur = float(blur_px(np.median(depth[seen]))) if seen.any() else 0.0
    return (cv2.GaussianBlur(img, (0, 0), blur) if blur > 0.05 else img), hits, dirs


def edge_pixels(part: np.ndarray, nz: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels an edge crosses, from what each pixel's centre ray met —
    ``part`` index, its normal's |z|, ``depth`` mm (H, W) each — a neighbour's differing:
    another part, a wall beside a top, a step down. An edge within a pixel lies between
    its centre and a neighbour's, so both are marked."""
    edge = np.zeros(part.shape, bool)
    for key, tol in ((part, 0.5), (nz, 0.05), (depth, 0.5)):
        for a in (0, 1):
            d = np.abs(np.diff(key, axis=a)) > tol
            lo, hi = [slice(None)] * 2, [slice(None)] * 2
            lo[a], hi[a] = slice(None, -1), slice(1, None)
            edge[tuple(lo)] |= d
            edge[tuple(hi)] |= d
    return edge


def area_rays(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(K·n², 2) pixel positions (u, v) of ``EDGE_SUB``² rays spread evenly over each pixel
    (``rows``, ``cols`` (K,)), a pixel's rays together: their mean is the pixel's area."""
    sub = (np.arange(EDGE_SUB) + 0.5) / EDGE_SUB - 0.5
    du, dv = (g.ravel() for g in np.meshgrid(sub, sub))
    return np.column_stack([(cols[:, None] + du).ravel(), (rows[:, None] + dv).ravel()])
