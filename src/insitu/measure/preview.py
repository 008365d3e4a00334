"""A picture of a point cloud without OpenGL: an oblique orthographic view, points z-buffered
and coloured by height (for reports, the README and headless runs)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_write_bytes
from insitu.geometry.camera import rotation_about


def cloud_picture(points: np.ndarray, size: tuple[int, int] = (900, 600),
                  azimuth_deg: float = 60.0, elevation_deg: float = 30.0,
                  z_exaggeration: float = 1.0) -> np.ndarray:
    """(H, W, 3) uint8 BGR image of points (N, 3) mm, coloured by z (turbo colour map)."""
    pts = np.asarray(points, float)
    pts = pts[np.isfinite(pts).all(1)]
    W, H = size
    img = np.full((H, W, 3), 255, np.uint8)
    if not len(pts):
        return img
    z = pts[:, 2]
    lo, hi = np.percentile(z, [0.5, 99.5])
    view = pts * [1, 1, z_exaggeration]
    R = rotation_about([1, 0, 0], np.deg2rad(elevation_deg - 90)) @ rotation_about(
        [0, 0, 1], np.deg2rad(azimuth_deg))
    q = (view - view.mean(0)) @ R.T                       # x right, y up, z toward the viewer
    span = np.ptp(q[:, :2], axis=0).max() or 1.0
    scale = 0.9 * min(W, H) / span
    u = np.rint(W / 2 + q[:, 0] * scale).astype(int)
    v = np.rint(H / 2 - q[:, 1] * scale).astype(int)
    ok = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    u, v, depth, z = u[ok], v[ok], q[ok, 2], z[ok]
    order = np.argsort(depth)                            # far first: near points overwrite
    colour_index = np.clip((z - lo) / max(hi - lo, 1e-9) * 255, 0, 255).astype(np.uint8)
    lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_TURBO)[:, 0]
    for du, dv in ((0, 0), (1, 0), (0, 1), (1, 1)):     # 2 × 2 px dots
        uu, vv = np.clip(u[order] + du, 0, W - 1), np.clip(v[order] + dv, 0, H - 1)
        img[vv, uu] = lut[colour_index[order]]
    cv2.putText(img, f"z {lo:.1f} .. {hi:.1f} mm", (10, H - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                (40, 40, 40), 1, cv2.LINE_AA)
    return img


def save_cloud_picture(points: np.ndarray, path: str | Path, **kw) -> None:
    path = Path(path)
    if not path.parent.is_dir():
        raise FormatError(f"{path}: folder {path.parent} does not exist")
    ok, buf = cv2.imencode(path.suffix or ".png", cloud_picture(points, **kw))
    if not ok:
        raise FormatError(f"{path}: cannot encode a picture of this type")
    atomic_write_bytes(path, buf.tobytes())
