"""The height models of Method 2: what they share (:class:`HeightModel`) and the one table of
them, :data:`HEIGHT_MODELS` — ``insitu scan --height-model``, :func:`insitu.services.height_model`
and the height calibration file's ``model`` field read it. A calibration file holds each
model's ``to_dict()`` under the model's name (``sheet``, ``paper``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from insitu.geometry.camera import CameraModel
from insitu.reconstruct.plate_models import PaperHeightModel, SheetHeightModel


@runtime_checkable
class HeightModel(Protocol):
    """A fitted height calibration as the reconstruction uses it."""

    name: str

    @property
    def z_range(self) -> tuple[float, float]:
        """The plate heights it was fitted over, (low, high) mm."""
        ...

    def points(self, camera: CameraModel, x_mm: float, u: np.ndarray, v: np.ndarray
               ) -> np.ndarray:
        """(N, 3) world mm of the centres (u, v) (N,) px of the line at offset ``x_mm``
        (through ``camera``, the one it was fitted through); NaN rows where it has none."""
        ...

    def to_dict(self) -> dict:
        """Its form in the calibration file (JSON-able)."""
        ...

    @classmethod
    def from_dict(cls, d: dict) -> "HeightModel": ...


@dataclass(frozen=True)
class HeightModelKind:
    """``model``: the class (``from_dict`` reads the file's form); ``description``: one line
    (CLI help); ``absent``: why a calibration may not hold it (empty: it always does)."""

    model: type[HeightModel]
    description: str
    absent: str = ""


HEIGHT_MODELS: dict[str, HeightModelKind] = {
    "sheet": HeightModelKind(SheetHeightModel, "ours, the default"),
    "paper": HeightModelKind(PaperHeightModel, "Li et al.'s P1 + P2",
                             "its recording has no line at offset 0 on the plate at height 0"),
}
