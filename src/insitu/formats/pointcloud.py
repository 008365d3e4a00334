"""Point clouds (formats.md §2): binary little-endian PLY written with Open3D, world frame, mm,
with optional per-point intensity, line index and quality."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import open3d as o3d

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_file

_ATTRIBUTES = ("intensity", "line", "quality")


@dataclass(frozen=True)
class PointCloud:
    """points: (N, 3) float64 mm, world frame. attributes: name → (N,) arrays (intensity,
    line index, quality)."""

    points: np.ndarray
    attributes: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.points)


def write_ply(path: str | Path, cloud: PointCloud) -> None:
    """Write ``cloud`` atomically (:func:`insitu.formats.atomic.atomic_file`)."""
    path = Path(path)
    if not path.parent.is_dir():
        raise FormatError(f"{path}: folder {path.parent} does not exist")
    if path.suffix.lower() != ".ply":
        raise FormatError(f"{path}: a point cloud is written as .ply")
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor(np.asarray(cloud.points, np.float64)))
    for name, values in cloud.attributes.items():
        arr = np.asarray(values)
        dtype = np.int32 if np.issubdtype(arr.dtype, np.integer) else np.float32
        pcd.point[name] = o3d.core.Tensor(arr.astype(dtype).reshape(-1, 1))
    with atomic_file(path, suffix=".ply") as tmp:
        if not o3d.t.io.write_point_cloud(str(tmp), pcd, write_ascii=False, compressed=False):
            raise FormatError(f"{path}: Open3D could not write the point cloud")


def read_ply(path: str | Path) -> PointCloud:
    """Read a PLY point cloud with whatever of intensity, line and quality it holds."""
    path = Path(path)
    if not path.is_file():
        raise FormatError(f"{path}: no such point cloud file")
    _check_header(path)
    pcd = o3d.t.io.read_point_cloud(str(path))
    if "positions" not in pcd.point or pcd.point.positions.shape[0] == 0:
        raise FormatError(f"{path}: no points (not a PLY point cloud, or empty)")
    pts = pcd.point.positions.numpy().astype(np.float64)
    attrs = {n: pcd.point[n].numpy().ravel() for n in _ATTRIBUTES if n in pcd.point}
    return PointCloud(pts, attrs)


def _check_header(path: Path) -> None:
    """FormatError unless the file starts with a complete PLY header (Open3D's reader
    crashes the process on some incomplete ones, e.g. one ending in ``comment``)."""
    with open(path, "rb") as f:
        head = f.read(65536)
    lines = head.split(b"\n")
    if lines[0].rstrip(b"\r") != b"ply":
        raise FormatError(f"{path}: not a PLY file (it does not start with 'ply')")
    if not any(line.rstrip(b"\r") == b"end_header" for line in lines[1:-1]):
        raise FormatError(f"{path}: incomplete PLY header (no 'end_header' line)")
