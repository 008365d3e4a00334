"""Locating a part: its reference (a mesh in its own frame, or a first scan) read once, a
cloud registered to it, the pose written to POSE.json (``insitu locate``; ``produce`` calls
:func:`locate_cloud` for each part)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from insitu.formats.images import read_image
from insitu.formats.mesh import is_mesh_file, read_mesh
from insitu.formats.pointcloud import PointCloud, read_ply
from insitu.formats.pose import save_pose
from insitu.formats.recipe import Recipe
from insitu.geometry.camera import CameraModel
from insitu.geometry.pose import flat_pose
from insitu.locate.part import LocateSettings, PartPose, locate_part
from insitu.locate.reference import PartReference, reference_from_cloud, reference_from_mesh


def load_reference(path: str | Path, settings: LocateSettings = LocateSettings(),
                   room_light: str | Path | None = None,
                   camera: CameraModel | None = None) -> PartReference:
    """The part's reference from ``path``: an STL/OBJ mesh or a PLY with faces (the part's own
    frame, mm), or a PLY point cloud — a first scan, whose world frame becomes the part's
    (its table found and taken away as ``settings`` say); with ``room_light``, the frame of
    ``camera`` (the scan's) that scan took, its outline fitted there
    (:mod:`insitu.locate.outline_fit`, checked by the scan's lines) — without the camera it
    cannot be placed, and the outline is the scan's own (its σ larger)."""
    path = Path(path)
    if is_mesh_file(path):
        v, t = read_mesh(path)
        return reference_from_mesh(v, t, path.name)
    cloud = read_ply(path)
    image = None
    if room_light is not None and camera is not None:
        image = read_image(room_light, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_ANYDEPTH,
                           expect=(camera.width, camera.height),
                           expected="the camera's frame is")
    return reference_from_cloud(cloud.points, path.name, settings.table_band_mm,
                                settings.table_z_mm, image, camera,
                                cloud.attributes.get("line"))


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
           camera: CameraModel | None = None, image: np.ndarray | None = None,
           reference_room_light: str | Path | None = None) -> PartPose:
    """Locate the part of ``reference`` in the cloud file ``cloud`` (measured through
    ``camera``, None: unknown; ``image``: its room-light frame of the part;
    ``reference_room_light``: a cloud reference's own frame, :func:`load_reference`) and
    write POSE.json ``out`` atomically (nothing is written when it is refused)."""
    measured = read_ply(cloud)
    ref = load_reference(reference, settings, reference_room_light, camera)
    pose = locate_cloud(ref, measured, settings, prefer_angle, camera, image)
    save_pose(out, pose.to_dict(), [str(reference), str(cloud)], prefer_angle, measured.rig)
    return pose


@dataclass(frozen=True)
class Located:
    """Where the part lies: ``T_world_part`` (4, 4) maps part mm into the world; the
    registration's ``fitness`` (0 … 1) and inlier ``rmse_mm``; ``image_edges``: the
    room-light frame's edge points that gave x, y and the turn (0: the scan's edges did)."""

    T_world_part: np.ndarray
    fitness: float
    rmse_mm: float
    image_edges: int = 0

    def pose(self) -> tuple[float, float, float]:
        """(x mm, y mm, angle_deg about +z)."""
        return flat_pose(self.T_world_part)


Locator = Callable[[PointCloud, "np.ndarray | None"], Located]


def recipe_locator(recipe: Recipe, camera: CameraModel | None = None) -> Locator:
    """``locate(cloud, room_light) -> Located`` against the recipe's reference (read once:
    :func:`insitu.services.locate.load_reference`), keeping a symmetric part's turn within
    the recipe's ``prefer_angle_deg``; ``camera``: the one the scans are measured through
    (:func:`insitu.services.height.scan_camera`; None: unknown, a less precise turn) and
    ``room_light`` its frame of the part, laser off (None: none), whose edges then give x, y
    and the turn; it raises the registration's one-line refusal (part not found, partly
    scanned, poor fit, ambiguous, not within the recipe's tolerance). ``locate.reference``."""
    settings = LocateSettings(tolerance_mm=recipe.tolerance[0],
                              turn_bound_deg=recipe.tolerance[1],
                              turn_tolerance_deg=recipe.turn_tolerance_deg)
    reference = load_reference(recipe.reference, settings, recipe.reference_room_light, camera)

    def locate(cloud: PointCloud, room_light: np.ndarray | None = None) -> Located:
        pose = locate_cloud(reference, cloud, settings, recipe.prefer_angle_deg, camera,
                            room_light)
        return Located(pose.T_world_part, pose.best.fitness, pose.best.rmse_mm,
                       pose.best.image_edges)
    locate.reference = reference
    return locate
