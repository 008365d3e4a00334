"""What the use cases share."""

from __future__ import annotations

from collections.abc import Callable

from insitu.formats.sequence import CameraSpec
from insitu.geometry.camera import CameraModel

Progress = Callable[[int, int], None]


def camera_model(spec: CameraSpec) -> CameraModel:
    """The camera of a file (formats.md ``camera``) as a model."""
    return CameraModel(spec.width, spec.height, spec.K_array, spec.dist_array, spec.R_array,
                       spec.t_array)
