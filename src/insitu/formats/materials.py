"""Materials: how each engraves under the station's laser — the table beside the pens that
``insitu engrave --material`` reads. A materials file::

    {"format": "insitu-materials/1",
     "laser": {"power_w": 20, "spot_um": 50},
     "materials": [{"name": "stainless-steel", "threshold_j_cm2": 1.8, "penetration_um": 0.48,
                    "hatch_mm": 0.02, "pen": {"name": "engrave-steel", "power_pct": 80,
                    "frequency_khz": 40, "mark_speed_mm_s": 800}, "source": "..."}]}

``laser``: the source's average power at 100 % and its 1/e² spot diameter at focus. Each
material: the threshold fluence F_th and effective penetration depth δ = 1/α of the
logarithmic ablation law, the pen (:mod:`insitu.formats.pens`) and hatch distance it is
engraved with, and where its constants come from. :meth:`Material.depth_per_pass_mm` is the
nominal depth one pass removes: the volume per pulse V = π w² δ ln²(F0 / F_th) / 4 with
F0 = 2E / (π w²) (Neuenschwander et al., Proc. SPIE 8243 (2012) 824307) times the pulses per
area f / (v · h). The engraving learns the real rate from its first measured passes; the
table is where it starts, and what an open-loop engraving would go by.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from insitu.errors import FormatError
from insitu.formats.bounds import within
from insitu.formats.pens import Pen, PenName
from insitu.formats.validation import one_of, read_json, unique_names, validation_message

MATERIALS_FORMAT = "insitu-materials/1"
Power, Spot = within("laser_power_w"), within("spot_um")
Threshold, Penetration, Hatch = (within("threshold_j_cm2"), within("penetration_um"),
                                 within("length_mm"))


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class LaserSource(_Strict):
    """The marking laser: ``power_w`` average power at 100 %, ``spot_um`` its 1/e² spot
    diameter at focus."""

    power_w: Power = 20.0
    spot_um: Spot = 50.0

    def peak_fluence_j_cm2(self, power_pct: float, frequency_khz: float) -> float:
        """A pulse's peak fluence F0 = 2E / (π w²) (J/cm²) at ``power_pct`` % and
        ``frequency_khz``, in focus."""
        w_cm = self.spot_um / 2 * 1e-4
        energy_j = self.power_w * power_pct / 100.0 / (frequency_khz * 1e3)
        return 2 * energy_j / (math.pi * w_cm ** 2)


class Material(_Strict):
    """One material: ablation constants (``threshold_j_cm2`` F_th, ``penetration_um`` δ),
    the ``pen`` and ``hatch_mm`` it is engraved with, and the ``source`` of its constants."""

    name: PenName
    description: str = ""
    threshold_j_cm2: Threshold
    penetration_um: Penetration
    hatch_mm: Hatch = 0.02
    pen: Pen
    source: str = ""

    def depth_per_pass_mm(self, laser: LaserSource, power_pct: float | None = None) -> float:
        """Nominal depth (mm) one pass of the pen removes from a flat floor in focus
        (``power_pct``: instead of the pen's); 0 below the threshold."""
        pen = self.pen
        pct = pen.power_pct if power_pct is None else power_pct
        log_f = math.log(max(laser.peak_fluence_j_cm2(pct, pen.frequency_khz), 1e-30)
                         / self.threshold_j_cm2)
        if log_f <= 0:
            return 0.0
        w_mm, delta_mm = laser.spot_um / 2e3, self.penetration_um * 1e-3
        volume = math.pi * w_mm ** 2 * delta_mm * log_f ** 2 / 4
        return volume * pen.frequency_khz * 1e3 / (pen.mark_speed_mm_s * self.hatch_mm)


class MaterialTable(_Strict):
    """The laser and the materials of a station."""

    laser: LaserSource = LaserSource()
    materials: Annotated[tuple[Material, ...], Field(min_length=1)]

    @model_validator(mode="after")
    def _names(self) -> "MaterialTable":
        unique_names(self.materials, "material", "materials")
        return self

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.materials)

    def softest(self) -> Material:
        """The material with the lowest ablation threshold: what a scan must never mark."""
        return min(self.materials, key=lambda m: m.threshold_j_cm2)

    def material(self, name: str, where: str = "material") -> Material:
        """The material called ``name``; FormatError naming ``where`` and the materials."""
        for m in self.materials:
            if m.name == name:
                return m
        raise FormatError(f"{where}: no material {name!r}; the materials are "
                          f"{one_of(self.names)}", field="material")


_NS_FIBRE = "ns Yb-fibre, 1064 nm; "
DEFAULT_MATERIALS = MaterialTable(materials=(
    Material(name="stainless-steel", description="stainless steel 304/316L",
             threshold_j_cm2=1.8, penetration_um=0.48, hatch_mm=0.02,
             pen=Pen(name="engrave-steel", colour="#c0c0c0", power_pct=80.0,
                     frequency_khz=40.0, mark_speed_mm_s=800.0),
             source=_NS_FIBRE + "thresholds of 1–5 J/cm² (Radmanesh & Kiani, Mater. Sci. "
             "Appl. 6 (2015) 521); removal of a few mm³/min at 20 W (Hribar et al., "
             "Nanomaterials 12 (2022) 232)"),
    Material(name="anodised-aluminium", description="aluminium 6061, 20 µm anodic layer",
             threshold_j_cm2=1.5, penetration_um=0.55, hatch_mm=0.02,
             pen=Pen(name="engrave-alu", colour="#8080ff", power_pct=60.0,
                     frequency_khz=40.0, mark_speed_mm_s=800.0),
             source=_NS_FIBRE + "ns ablation of Al 6061 (Terragni et al., arXiv:2108.11665, "
             "2021)"),
    Material(name="beech", description="beech, a hardwood, across the grain",
             threshold_j_cm2=0.7, penetration_um=1.6, hatch_mm=0.025,
             pen=Pen(name="engrave-wood", colour="#c08040", power_pct=25.0,
                     frequency_khz=40.0, mark_speed_mm_s=2000.0),
             source=_NS_FIBRE + "ablation rates of wood with Nd:YAG pulses (Panzner et al., "
             "Appl. Surf. Sci. 127–129 (1998) 787)"),
))
"""The built-in table: a 20 W source with a 50 µm spot and three materials."""


def read_materials(path: str | Path) -> MaterialTable:
    """Read a materials file (``format`` insitu-materials/1); FormatError naming the file,
    the material and the field."""
    path = Path(path)
    raw = read_json(path, missing="no such materials file")
    if not isinstance(raw, dict) or raw.get("format") != MATERIALS_FORMAT:
        got = raw.get("format") if isinstance(raw, dict) else type(raw).__name__
        raise FormatError(f"{path}: format: expected {MATERIALS_FORMAT!r}, got {got!r} "
                          "(not a materials file)")
    try:
        return MaterialTable.model_validate({k: v for k, v in raw.items() if k != "format"})
    except ValidationError as e:
        raise FormatError(validation_message(path, e)) from None
