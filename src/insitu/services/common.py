"""What the use cases share."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from pydantic import BaseModel

from insitu.formats.sequence import CameraSpec
from insitu.geometry.camera import CameraModel

Progress = Callable[[int, int], None]


def save_with_picture(out: str | Path, result: BaseModel, draw: Callable[[Path], None]) -> None:
    """Write ``result`` to ``out`` (JSON) and ``draw`` its picture beside it (.png), both
    atomically: nothing is left behind if either fails."""
    from insitu.formats.json_file import save_json_model

    out = Path(out)
    png = out.with_suffix(".png")
    draw(png)
    try:
        save_json_model(out, result)
    except BaseException:
        png.unlink(missing_ok=True)
        raise


def camera_model(spec: CameraSpec) -> CameraModel:
    """The camera of a file (docs/formats.md, recorded sequence ``camera``) as a model."""
    return CameraModel(spec.width, spec.height, spec.K_array, spec.dist_array, spec.R_array,
                       spec.t_array)
