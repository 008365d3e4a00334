"""The evented core of the application (no Qt): what the operator has connected, measured,
placed and planned. Widgets observe these signals (psygnal) and call the methods; nothing
here draws or blocks."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from psygnal import Signal

from insitu.formats.pointcloud import PointCloud
from insitu.formats.project import RigChoice
from insitu.marking import MarkJob
from insitu.marking import Placement
from insitu.services.mark import PlanOutcome
from insitu.ui.model.scene_data import follow_code_hatch


class PlacementHistory:
    """The placed patterns with undo/redo: every change is a new state (a tuple of
    :class:`Placement`). Consecutive changes with the same ``merge_key`` (one mouse drag)
    make one undo step."""

    changed = Signal()

    def __init__(self) -> None:
        self._states: list[tuple[Placement, ...]] = [()]
        self._index = 0
        self._merge_key: object = None

    @property
    def items(self) -> tuple[Placement, ...]:
        return self._states[self._index]

    def push(self, items: tuple[Placement, ...], merge_key: object = None) -> None:
        """Make ``items`` the current state (undoable)."""
        items = tuple(items)
        if items == self.items:
            return
        del self._states[self._index + 1:]
        if merge_key is not None and merge_key == self._merge_key and self._index > 0:
            self._states[self._index] = items
        else:
            self._states.append(items)
            self._index += 1
        self._merge_key = merge_key
        self.changed.emit()

    def reset(self, items: tuple[Placement, ...] = ()) -> None:
        """Start a new history at ``items`` (nothing to undo)."""
        self._states, self._index, self._merge_key = [tuple(items)], 0, None
        self.changed.emit()

    def can_undo(self) -> bool:
        return self._index > 0

    def can_redo(self) -> bool:
        return self._index < len(self._states) - 1

    def undo(self) -> None:
        if self.can_undo():
            self._index -= 1
            self._merge_key = None
            self.changed.emit()

    def redo(self) -> None:
        if self.can_redo():
            self._index += 1
            self._merge_key = None
            self.changed.emit()


class Session:
    """Everything one project holds. Signals carry no payload; read the attributes."""

    rig_changed = Signal()
    cloud_changed = Signal()
    live_points_added = Signal(object)      # (K, 3) float64 mm: points of one scan frame
    selection_changed = Signal()
    plans_changed = Signal()

    def __init__(self) -> None:
        self.rig_choice = RigChoice()
        self.height_cal_path: Path | None = None
        self.height_cal = None              # insitu.rig.files.HeightCalibration
        self.field_path: Path | None = None
        self.camera_cal_path: Path | None = None
        self.cloud: PointCloud | None = None
        self.cloud_path: Path | None = None     # where the cloud is on disk, None if unsaved
        self.placements = PlacementHistory()
        self.selected = -1
        self.plans: list[PlanOutcome] = []
        self.project_path: Path | None = None
        self.placements.changed.connect(self._clamp_selection)

    # -- cloud ---------------------------------------------------------------------------
    def set_cloud(self, cloud: PointCloud | None, path: Path | None = None) -> None:
        self.cloud, self.cloud_path = cloud, path
        self.plans = []
        self.cloud_changed.emit()

    # -- placements ----------------------------------------------------------------------
    def current(self) -> Placement | None:
        items = self.placements.items
        return items[self.selected] if 0 <= self.selected < len(items) else None

    def select(self, index: int) -> None:
        index = index if 0 <= index < len(self.placements.items) else -1
        if index != self.selected:
            self.selected = index
            self.selection_changed.emit()

    def add_placement(self, placement: Placement) -> None:
        self.placements.push(self.placements.items + (placement,))
        self.select(len(self.placements.items) - 1)

    def remove_selected(self) -> None:
        items = list(self.placements.items)
        if 0 <= self.selected < len(items):
            del items[self.selected]
            self.placements.push(tuple(items))

    def update_selected(self, merge_key: object = None, **changes) -> None:
        """Change fields of the selected placement (``at_mm``, ``width_mm``, ...); a code
        hatched along its modules stays so (``scene_data.follow_code_hatch``)."""
        items = list(self.placements.items)
        if not 0 <= self.selected < len(items):
            return
        old = items[self.selected]
        items[self.selected] = follow_code_hatch(old, replace(old, **changes))
        self.placements.push(tuple(items), merge_key)

    def _clamp_selection(self) -> None:
        n = len(self.placements.items)
        if self.selected >= n:
            self.selected = n - 1
            self.selection_changed.emit()
        elif self.selected < 0 and n:
            self.selected = 0
            self.selection_changed.emit()

    # -- plans ---------------------------------------------------------------------------
    def set_plans(self, plans: list[PlanOutcome]) -> None:
        self.plans = list(plans)
        self.plans_changed.emit()

    def job(self) -> MarkJob | None:
        """One job marking every placement in order (each was checked by ``plan_mark``), or
        None while any is refused or not yet planned."""
        from insitu.services.mark import joined

        if len(self.plans) != len(self.placements.items):
            return None
        return joined(self.plans)
