"""Triangle meshes (STL, PLY, OBJ) in mm, read and written with Open3D: a simulated part, or a
part's reference for ``insitu locate`` in its own frame. A PLY holds a mesh when its header
declares faces; otherwise it is a point cloud (:mod:`insitu.formats.pointcloud`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from insitu.errors import FormatError
from insitu.formats.atomic import atomic_file
from insitu.formats.limits import MAX_CLOUD_BYTES, check_file
from insitu.formats.pointcloud import ply_face_count

MESH_SUFFIXES = (".stl", ".ply", ".obj")


def is_mesh_file(path: str | Path) -> bool:
    """Whether ``path`` is an STL or OBJ file, or a PLY with faces."""
    path = Path(path)
    suffix = path.suffix.lower()
    return suffix in (".stl", ".obj") or (suffix == ".ply" and ply_face_count(path) > 0)


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (N, 3) float64 mm, triangles (M, 3) int32) of an STL, PLY or OBJ file,
    duplicated vertices merged. FormatError when it is missing, unreadable, too large, has
    no triangles, non-finite vertices or bad indices."""
    path = Path(path)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise FormatError(f"{path}: unsupported mesh format {path.suffix!r}; "
                          "expected .stl, .ply or .obj")
    check_file(path, MAX_CLOUD_BYTES, "mesh", missing="no such mesh file")
    import open3d as o3d

    try:
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            mesh = o3d.io.read_triangle_mesh(str(path))
    except Exception as exc:                     # noqa: BLE001 — Open3D raises RuntimeError
        raise FormatError(f"{path}: unreadable mesh ({exc})".splitlines()[0]) from None
    mesh.remove_duplicated_vertices()
    v, t = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.triangles, np.int64)
    if len(t) == 0 or len(v) == 0:
        raise FormatError(f"{path}: no triangles (not a readable STL/PLY/OBJ mesh)")
    if not np.all(np.isfinite(v)) or t.min() < 0 or t.max() >= len(v):
        raise FormatError(f"{path}: invalid mesh (non-finite vertices or bad triangle indices)")
    return v, t.astype(np.int32)


def write_mesh(path: str | Path, vertices: np.ndarray, triangles: np.ndarray) -> None:
    """Write a mesh (vertices (N, 3) mm, triangles (M, 3)) as STL, PLY (binary) or OBJ by
    ``path``'s suffix, atomically; FormatError for another suffix or when Open3D fails."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise FormatError(f"{path}: a mesh is written as .stl, .ply or .obj")
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(vertices, float)),
                                     o3d.utility.Vector3iVector(np.array(triangles, np.int32)))
    mesh.compute_triangle_normals()
    with atomic_file(path, suffix=suffix) as tmp:
        if not o3d.io.write_triangle_mesh(str(tmp), mesh, write_ascii=False):
            raise FormatError(f"{path}: Open3D could not write the mesh")
