"""The evented core of the application (no Qt): what the operator has connected, measured,
placed and planned. Widgets observe these signals (psygnal) and call the methods; nothing
here draws or blocks."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from psygnal import Signal

from insitu.formats.pens import DEFAULT_PENS, PenTable
from insitu.formats.pointcloud import PointCloud
from insitu.formats.project import RigChoice
from insitu.marking import MarkJob, Placement
from insitu.services.plan import PlanOutcome
from insitu.ui.model.scene_data import follow_code_hatch


class PlacementHistory:
    """The placed patterns and the cloud they are placed on, with undo/redo: every change is
    a new state (a tuple of :class:`Placement`, and the cloud of that moment as
    ``(PointCloud | None, path | None)``), so a cloud replaced by a scan comes back with Undo.
    Consecutive changes with the same ``merge_key`` (one mouse drag) make one undo step."""

    changed = Signal()

    def __init__(self) -> None:
        self._states: list[tuple[Placement, ...]] = [()]
        self._clouds: list[tuple] = [(None, None)]
        self._index = 0
        self._merge_key: object = None

    @property
    def items(self) -> tuple[Placement, ...]:
        return self._states[self._index]

    @property
    def cloud(self) -> tuple:
        """(cloud, path) of the current state."""
        return self._clouds[self._index]

    def _step(self, items: tuple[Placement, ...], cloud: tuple, merge_key: object) -> None:
        del self._states[self._index + 1:], self._clouds[self._index + 1:]
        if merge_key is not None and merge_key == self._merge_key and self._index > 0:
            self._states[self._index], self._clouds[self._index] = items, cloud
        else:
            self._states.append(items)
            self._clouds.append(cloud)
            self._index += 1
        self._merge_key = merge_key
        self.changed.emit()

    def push(self, items: tuple[Placement, ...], merge_key: object = None) -> None:
        """Make ``items`` the current state (undoable)."""
        items = tuple(items)
        if items != self.items:
            self._step(items, self.cloud, merge_key)

    def push_cloud(self, cloud, path=None) -> None:
        """Make ``cloud`` (at ``path``) the current state's cloud (undoable)."""
        if cloud is not self.cloud[0] or path != self.cloud[1]:
            self._step(self.items, (cloud, path), None)

    def cloud_written(self, cloud, path) -> None:
        """``cloud`` is on disk at ``path`` now (in every state that holds it)."""
        self._clouds = [(c, path) if c is cloud else (c, p) for c, p in self._clouds]

    def rewrite(self, change) -> None:
        """Apply ``change`` (Placement → Placement) to every state, undo and redo included
        (for what is not undoable itself, such as a pen renamed or removed)."""
        before = self.items
        self._states = [tuple(change(p) for p in state) for state in self._states]
        if self.items != before:
            self.changed.emit()

    def reset(self, items: tuple[Placement, ...] = ()) -> None:
        """Start a new history at ``items`` on the current cloud (nothing to undo)."""
        self._states, self._clouds = [tuple(items)], [self.cloud]
        self._index, self._merge_key = 0, None
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


@dataclass(frozen=True)
class JobFile:
    """A mark job opened from ``path`` (made by ``insitu mark`` or exported): marked as it
    is, its journal beside it, as ``insitu job run`` does."""

    path: Path
    job: MarkJob


class Session:
    """Everything one project holds. Signals carry no payload; read the attributes."""

    rig_changed = Signal()
    cloud_changed = Signal()
    live_points_added = Signal(object)      # (K, 3) float64 mm: points of one scan frame
    selection_changed = Signal()
    plans_changed = Signal()
    pens_changed = Signal()
    job_file_changed = Signal()

    def __init__(self) -> None:
        self.rig_choice = RigChoice()
        self.height_cal_path: Path | None = None
        self.height_cal = None              # insitu.formats.calibration.HeightCalibration
        self.field_path: Path | None = None
        self.camera_cal_path: Path | None = None
        self.cloud: PointCloud | None = None
        self.cloud_path: Path | None = None     # where the cloud is on disk, None if unsaved
        self.placements = PlacementHistory()
        self.selected = -1
        self.plans: list[PlanOutcome] = []
        self.project_path: Path | None = None
        self.pens: PenTable = DEFAULT_PENS
        self.job_file: JobFile | None = None
        self.placements.changed.connect(self._follow_cloud)
        self.placements.changed.connect(self._clamp_selection)
        self.placements.changed.connect(self._placed)

    # -- cloud ---------------------------------------------------------------------------
    def set_cloud(self, cloud: PointCloud | None, path: Path | None = None) -> None:
        """Place on ``cloud`` (at ``path``; None: not on disk yet) from now on: one undo
        step (Undo brings back the cloud before)."""
        self.placements.push_cloud(cloud, path)

    def cloud_written(self, path: Path | None) -> None:
        """The session's cloud was written to ``path`` (a project saved)."""
        self.placements.cloud_written(self.cloud, path)
        self.cloud_path = path

    def _follow_cloud(self) -> None:
        cloud, path = self.placements.cloud
        if cloud is not self.cloud or path != self.cloud_path:
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

    # -- pens ----------------------------------------------------------------------------
    def set_pens(self, pens: PenTable | None, renamed: tuple[str, str] | None = None) -> None:
        """The pen table the placements are planned with (None: :data:`DEFAULT_PENS`); a
        placement naming a pen ``renamed`` (old, new) follows it, one naming a pen the table
        no longer has takes the default — in every state of the undo history, so that an
        undo never brings back a pen that is gone."""
        pens = pens or DEFAULT_PENS
        if pens == self.pens:
            return
        self.pens = pens
        names = dict([renamed] if renamed else [])
        self.placements.rewrite(lambda p: p if p.pen is None or p.pen in pens.names and (
            p.pen not in names) else replace(p, pen=names.get(p.pen)))
        self.pens_changed.emit()

    def pen_of(self, placement: Placement):
        """The pen ``placement`` is marked with."""
        return self.pens.pen(placement.pen)

    # -- a job file ----------------------------------------------------------------------
    def set_job_file(self, job_file: JobFile | None) -> None:
        """Mark ``job_file`` instead of the placements (None: the placements again)."""
        if job_file is not self.job_file:
            self.job_file = job_file
            self.job_file_changed.emit()

    def _placed(self) -> None:
        """Placing a pattern ends the opened job: the placements are marked again."""
        if self.placements.items:
            self.set_job_file(None)

    # -- plans ---------------------------------------------------------------------------
    def set_plans(self, plans: list[PlanOutcome]) -> None:
        self.plans = list(plans)
        self.plans_changed.emit()

    def job(self) -> MarkJob | None:
        """The opened job file's job, else one job marking every placement in order (each
        was checked by :func:`insitu.services.plan.plan_placements`), or None while any is
        refused or not yet planned."""
        from insitu.services.plan import joined

        if self.job_file is not None:
            return self.job_file.job
        if (not self.plans or len(self.plans) != len(self.placements.items)
                or any(o.plan is None for o in self.plans)):
            return None
        return joined(self.plans)
