"""What ``insitu engrave`` is asked (:class:`EngraveRequest`) and what it gives back
(:class:`EngraveOutcome`), with the callbacks it reports through."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from insitu.formats.calibration import HeightCalibration
from insitu.formats.materials import DEFAULT_MATERIALS, MaterialTable
from insitu.formats.pointcloud import PointCloud
from insitu.marking import Placement
from insitu.marking.engrave_depth import DepthMap, DepthSettings
from insitu.marking.engrave_record import EngraveAsk, EngraveRecord

NO_HEIGHT_CAL = ("warning: no height calibration: the depth scans' scale is the light plane's "
                 "alone, ≈ 0.4 % of the depth within 30 mm of the field's centre, up to ≈ 4 % "
                 "near its edge")


LOOP_DEPTH = DepthSettings(faced_band_mm=0.0)
"""How the engraving maps its pocket between rounds: the cells beside the wall facing the
camera are kept (a pocket's depth leaves them out; in the loop that took beech's 6 × 6 mm
pocket's 95 % from 21.3 / 22.8 to 21.9 / 25.1 µm on the tune seeds 0 / 2)."""


@dataclass(frozen=True)
class EngraveRequest:
    """An engraving: ``placement`` (world frame) on ``cloud`` (the surface before it) to
    ``depth_mm``, measured every ``rescan_every`` passes at most, ``material`` of
    ``materials``; the record, jobs and pictures in ``report_dir``. ``height_cal``: the
    depth scans' heights (None: the light plane alone); ``spacing_mm``: their lines';
    ``resume``: go on with the engraving in ``report_dir`` (measured first);
    ``open_loop_passes``: instead, this many passes everywhere and nothing measured (what
    counting passes gives); ``materials_from``: where ``materials`` was read (said once)."""

    report_dir: Path
    placement: Placement
    cloud: PointCloud
    depth_mm: float
    rescan_every: int = 10
    material: str = "stainless-steel"
    materials: MaterialTable = DEFAULT_MATERIALS
    height_cal: HeightCalibration | None = None
    spacing_mm: float = 0.1
    settings: DepthSettings = field(default_factory=lambda: LOOP_DEPTH)
    resume: bool = False
    open_loop_passes: int | None = None
    materials_from: str = "the built-in table"

    def ask(self) -> EngraveAsk:
        p = self.placement
        return EngraveAsk(pattern=p.pattern, at_mm=p.at_mm, width_mm=p.width_mm,
                          rotate_deg=p.rotate_deg, depth_mm=self.depth_mm,
                          rescan_every=self.rescan_every, material=self.material,
                          open_loop_passes=self.open_loop_passes)


@dataclass(frozen=True)
class EngraveOutcome:
    """How it ended (``record.state``: done, held, cancelled), the ``record`` and the last
    depth map (None: never measured)."""

    record: EngraveRecord
    last: DepthMap | None


Notify = Callable[[str], None]
Measured = Callable[[DepthMap, dict], None]     # each measurement: its map, its summary
