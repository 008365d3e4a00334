"""The scan-head driver: a mark job → low-level galvo commands (MeerK40t balormk's driver).

Each 3-D target becomes mirror angles and a focus shift with the two-mirror kinematics
(Mikkelstrup et al. Eqs. 3–5), through a field correction when one is configured. Per path
(one list), with the path's laser, delays and wobble (:meth:`MarkJob.path_laser` …):

    [set_jump_speed]  jump_abs_3d  jump_delay  [set_power set_frequency set_mark_speed]
    [set_wobble]  laser_on  laser_on_delay  mark_abs_3d …(polygon_delay at corners)…
    laser_off_delay  laser_off  mark_delay

and for each further pass ``jump_abs_3d jump_delay laser_on … mark_delay`` again (a path's passes
are one list: a cut path marked again repeats them all). Settings are sent only when they change;
``set_wobble`` in every list whose path wobbles (it holds for its list only). The whole job is
compiled, and checked against the field and the focus range, before the first command is sent
(:mod:`.run` executes it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from insitu.devices.galvo import Command, FieldCorrection, joint_from_targets
from insitu.formats.pens import Wobble
from insitu.geometry.beams import TwoMirrorHead
from insitu.geometry.field import check_in_field
from insitu.marking.checks import Limits, check_targets, point_name
from insitu.marking.job import LaserParams, MarkJob, Timing, corner_delays_us


@dataclass
class _State:
    """What the head is set to (None: unknown, send it)."""

    power: float | None = None
    frequency: float | None = None
    mark_speed: float | None = None
    jump_speed: float | None = None


@dataclass(frozen=True)
class GalvoDriver:
    """``head``: nominal two-mirror kinematics; ``limits``: field and focus range (its
    ``head`` is set to ``head``); ``correction``: (N, 2) → (N, 2) field correction or None;
    ``timing``: delays used when the job carries none."""

    head: TwoMirrorHead
    limits: Limits = field(default_factory=Limits)
    correction: FieldCorrection | None = None
    timing: Timing = field(default_factory=Timing)

    def __post_init__(self) -> None:
        if self.limits.head is not self.head:
            object.__setattr__(self, "limits", Limits(self.limits.field_size_mm,
                                                      self.limits.z_range_mm,
                                                      self.limits.max_slope_deg, self.head))

    @classmethod
    def from_config(cls, head_config, correction: FieldCorrection | None = None,
                    timing: Timing | None = None) -> "GalvoDriver":
        """From the scan head's geometry (a :class:`~insitu.formats.rig.ScanHeadGeometry`, or
        its file :class:`~insitu.formats.rig.ScanHeadConfig`)."""
        return cls(TwoMirrorHead.of(head_config), Limits.of(head_config), correction,
                   timing or Timing())

    def joints(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) targets, mm → (N, 3) [alpha_x_deg, alpha_y_deg, focus_mm]."""
        return joint_from_targets(self.head, points, self.correction)

    def check(self, job: MarkJob) -> None:
        """SafetyError if any target is outside the field (where its corrected beam crosses
        z = 0) or the focus range."""
        pts = np.vstack([p.points for p in job.paths]) if job.paths else np.zeros((0, 3))
        check_targets(pts, self.limits)
        if self.correction is not None and len(pts):
            j = self.joints(pts)
            x, y = self.head.forward(2 * np.radians(j[:, 0]), 2 * np.radians(j[:, 1]), 0.0)
            check_in_field(np.column_stack([x, y]), self.limits.field_size_mm,
                           lambda i, field: f"{point_name(pts, i)} is outside the scan field "
                           f"{field} after the field correction", at=pts)

    def compile(self, job: MarkJob, first_path: int = 0) -> list[list[Command]]:
        """Check the job, then one command list per path from ``first_path`` on (settings
        state fresh at ``first_path``). Raises SafetyError before anything is sent."""
        self.check(job)
        state = _State()
        return [self._path(job.paths[i].points, job.path_laser(i),
                           job.path_timing(i, self.timing), state, job.path_passes(i),
                           job.path_wobble(i))
                for i in range(first_path, len(job.paths))]

    def _path(self, pts: np.ndarray, laser: LaserParams, t: Timing, s: _State, passes: int = 1,
              wobble: Wobble | None = None) -> list[Command]:
        j = self.joints(pts)
        cmds: list[Command] = []
        _set(cmds, s, "jump_speed", "set_jump_speed", laser.jump_speed_mm_s)
        corners = corner_delays_us(pts, t)
        marks = j[1:] if len(j) > 1 else j[:1]         # a one-point path marks a dot
        for n in range(passes):
            cmds += [Command("jump_abs_3d", tuple(map(float, j[0]))),
                     Command("jump_delay", (t.jump_delay_us,))]
            if n == 0:
                _set(cmds, s, "power", "set_power", laser.power_pct)
                _set(cmds, s, "frequency", "set_frequency", laser.frequency_khz)
                _set(cmds, s, "mark_speed", "set_mark_speed", laser.mark_speed_mm_s)
                if wobble is not None:
                    cmds.append(Command("set_wobble", (float(wobble.amplitude_mm), float(
                        wobble.hz(laser.mark_speed_mm_s)))))
            cmds += [Command("laser_on"), Command("laser_on_delay", (t.laser_on_delay_us,))]
            for k, q in enumerate(marks, start=1):
                cmds.append(Command("mark_abs_3d", tuple(map(float, q))))
                if k < len(corners) and corners[k] > 0:
                    cmds.append(Command("polygon_delay", (float(corners[k]),)))
            cmds += [Command("laser_off_delay", (t.laser_off_delay_us,)), Command("laser_off"),
                     Command("mark_delay", (t.mark_delay_us,))]
        return cmds

    def preview(self, job: MarkJob, outline: str = "hull", speed_mm_s: float = 1000.0,
                repeat: int = 1) -> list[Command]:
        """Pilot-laser preview, the marking laser never on: ``outline`` "hull" (bounding
        polygon of all points), "bbox" (x-y bounding box) or "paths" (every path), drawn
        ``repeat`` times at ``speed_mm_s``."""
        self.check(job)
        loops = preview_outlines(job, outline)
        cmds = [Command("set_jump_speed", (job.laser.jump_speed_mm_s,)),
                Command("set_mark_speed", (float(speed_mm_s),))]
        for _ in range(max(int(repeat), 1)):
            for loop in loops:
                j = self.joints(loop)
                cmds += [Command("jump_abs_3d", tuple(map(float, j[0]))), Command("pilot_on")]
                cmds += [Command("mark_abs_3d", tuple(map(float, q))) for q in j[1:]]
                cmds.append(Command("pilot_off"))
        return cmds


def _set(cmds: list[Command], s: _State, key: str, op: str, value: float) -> None:
    if getattr(s, key) != value:
        setattr(s, key, value)
        cmds.append(Command(op, (float(value),)))


def preview_outlines(job: MarkJob, outline: str = "hull") -> list[np.ndarray]:
    """Closed (or open, for "paths") 3-D polylines to draw with the pilot laser, mm."""
    if outline == "paths":
        return [p.points for p in job.paths]
    pts = np.vstack([p.points for p in job.paths])
    if outline == "hull":
        try:
            idx = ConvexHull(pts[:, :2]).vertices
        except (QhullError, ValueError):
            idx = np.array([int(np.argmin(pts[:, 0] + pts[:, 1])),
                            int(np.argmax(pts[:, 0] + pts[:, 1]))])
        loop = pts[idx]
    elif outline == "bbox":
        lo, hi = pts[:, :2].min(0), pts[:, :2].max(0)
        corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        near = np.argmin(((pts[None, :, :2] - corners[:, None]) ** 2).sum(-1), axis=1)
        loop = np.column_stack([corners, pts[near, 2]])
    else:
        raise ValueError(f"preview outline {outline!r}: expected 'hull', 'bbox' or 'paths'")
    return [np.vstack([loop, loop[:1]])]
