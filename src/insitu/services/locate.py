"""Locating a part: its reference (a mesh in its own frame, or a first scan) read once, a
cloud registered to it, the pose written to POSE.json (``insitu locate``; ``produce`` calls
:func:`locate_cloud` for each part)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from insitu.formats.mesh import is_mesh_file, read_mesh
from insitu.formats.pointcloud import PointCloud, read_ply
from insitu.geometry.camera import CameraModel
from insitu.locate.part import LocateSettings, PartPose, locate_part
from insitu.locate.reference import (PartReference, reference_from_cloud,
                                           reference_from_mesh)
from insitu.formats.pose import save_pose


def load_reference(path: str | Path, settings: LocateSettings = LocateSettings()
                   ) -> PartReference:
    """The part's reference from ``path``: an STL/OBJ mesh or a PLY with faces (the part's own
    frame, mm), or a PLY point cloud — a first scan, whose world frame becomes the part's
    (its table found and taken away as ``settings`` say)."""
    path = Path(path)
    if is_mesh_file(path):
        v, t = read_mesh(path)
        return reference_from_mesh(v, t, path.name)
    cloud = read_ply(path)
    return reference_from_cloud(cloud.points, path.name, settings.table_band_mm,
                                settings.table_z_mm)


def locate_cloud(reference: PartReference, cloud: PointCloud,
                 settings: LocateSettings = LocateSettings(),
                 prefer_angle: tuple[float, float] | None = None,
                 camera: CameraModel | None = None,
                 image: np.ndarray | None = None) -> PartPose:
    """:func:`~insitu.locate.part.locate_part` of a measured cloud (its scan lines used
    for the edges when it records them; ``camera``: the one it was measured through, see
    :func:`insitu.services.height.scan_camera`; ``image``: that camera's room-light frame of
    the part, for its edges). LocateRefused (a MeasurementError) names why when no pose is
    given."""
    return locate_part(reference, cloud.points, settings, prefer_angle,
                       lines=cloud.attributes.get("line"), camera=camera, image=image)


def locate(reference: str | Path, cloud: str | Path, out: str | Path,
           settings: LocateSettings = LocateSettings(),
           prefer_angle: tuple[float, float] | None = None,
           camera: CameraModel | None = None, image: np.ndarray | None = None) -> PartPose:
    """Locate the part of ``reference`` in the cloud file ``cloud`` (measured through
    ``camera``, None: unknown; ``image``: its room-light frame of the part) and write
    POSE.json ``out`` atomically (nothing is written when it is refused)."""
    measured = read_ply(cloud)
    pose = locate_cloud(load_reference(reference, settings), measured, settings, prefer_angle,
                        camera, image)
    save_pose(out, pose.to_dict(), [str(reference), str(cloud)], prefer_angle, measured.rig)
    return pose
