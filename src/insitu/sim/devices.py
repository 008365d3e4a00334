"""The simulated devices: a camera that sees what the simulated scan head draws on the
simulated workpiece, the Z stage carrying the plate, and a galvo controller whose marks burn
into the workpiece. All share one :class:`~insitu.sim.world.SimWorld`;
:func:`sim_devices` opens them as a station's devices.

The controller (:mod:`insitu.sim.controller`) executes the command lists and burns the marks.
"""

from __future__ import annotations

import numpy as np

from insitu.devices.backends import Devices
from insitu.devices.protocols import check_in_field
from insitu.errors import DeviceError, SafetyError
from insitu.sim.clock import roi_size
from insitu.sim.controller import SimController
from insitu.sim.marks import RoomLightView, render_inspection
from insitu.sim.render import NOMINAL_EXPOSURE_MS
from insitu.sim.scene import Scene
from insitu.sim.world import LaserState, SimWorld


class SimCamera:
    """Sees the world: the laser line, lines or spot on the parts, a calibration board in
    view, or room light. Each frame advances the world's station clock by what it would
    take (:mod:`insitu.sim.clock`: the head's jump to its list, the exposure, the readout of
    the region of interest); drawing it counts as the simulator's CPU."""

    def __init__(self, world: SimWorld):
        self.world = world
        self.width, self.height = world.rig.camera.width, world.rig.camera.height
        self.exposure_ms = NOMINAL_EXPOSURE_MS
        self.roi: tuple[int, int, int, int] | None = None
        self._frames_left: int | None = None

    def set_exposure(self, exposure_ms: float) -> None:
        self.exposure_ms = float(exposure_ms)

    def set_region_of_interest(self, roi: tuple[int, int, int, int] | None) -> None:
        """Read out only the pixels u0 ≤ u < u1, v0 ≤ v < v1 (``roi`` = (u0, v0, u1, v1),
        widened to the sensor's steps: 16 columns, 2 rows; None: the whole frame). A frame
        then reads out faster; the pixels outside it come as 0. Moving a region of the same
        size while grabbing (OffsetX, OffsetY written between frames) takes
        ``roi_move_ms`` of the station's time."""
        if roi is None:
            self.roi = None
            return
        u0, v0, u1, v1 = (int(np.floor(roi[0] / 16) * 16), int(np.floor(roi[1] / 2) * 2),
                          int(np.ceil(roi[2] / 16) * 16), int(np.ceil(roi[3] / 2) * 2))
        u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, self.width), min(v1, self.height)
        if not (u0 < u1 and v0 < v1):
            raise DeviceError(f"simulated camera: region of interest {list(roi)} holds no "
                              f"pixel of the {self.width}×{self.height} frame")
        new = (u0, v0, u1, v1)
        if (self.roi is not None and self.roi != new and roi_size(self.roi, 0, 0)
                == roi_size(new, 0, 0)):
            self.world.clock.advance("frames", self.world.timing.roi_move_ms * 1e-3)
        self.roi = new

    def fail_after(self, frames: int | None) -> None:
        """Fault injection (tests, benchmarks): after ``frames`` more frames every grab
        raises DeviceError, as a camera whose cable came loose (None: deliver again)."""
        self._frames_left = frames

    def _deliver(self) -> None:
        if self._frames_left is not None:
            if self._frames_left <= 0:
                raise DeviceError("simulated camera: gave no frame (fault injected)")
            self._frames_left -= 1

    def grab(self, timeout_s: float = 5.0) -> np.ndarray:
        self._deliver()
        with self.world.clock.simulating():
            image = self._render()
        self._tick()
        if self.roi is not None:
            u0, v0, u1, v1 = self.roi
            inside = image[v0:v1, u0:u1].copy()
            image[:] = 0
            image[v0:v1, u0:u1] = inside
        return image

    def _render(self) -> np.ndarray:
        if self.world.board is not None:
            return self.world.board.frame(self.world.laser)
        r, laser = self.world.renderer(), self.world.laser
        if laser.kind == "line":
            return r.line_frame(laser.start, laser.end, self.exposure_ms, laser.focus_z)
        if laser.kind == "lines":
            return r.lines_frame(laser.lines, self.exposure_ms, laser.focus_z)
        if laser.kind == "spot":
            return r.spot_frame(laser.start, self.exposure_ms, laser.focus_z)
        return r.ambient_frame(self.exposure_ms)

    def _exposure_now_ms(self) -> float:
        """The exposure of the frame being taken."""
        return self.exposure_ms

    def _tick(self) -> None:
        """The frame's station seconds (:meth:`SimTiming.frame_s`) onto the world's clock;
        the head's jump to its list counts once, in the first frame after it. A frame of
        lines is exposed for the light they need at the scan's power (the camera's exposure
        says how much light), in whole passes over them (:meth:`SimTiming.exposure_s`)."""
        w, t = self.world, self.world.timing
        rows, cols = roi_size(self.roi, self.width, self.height)
        exposure_ms = self._exposure_now_ms()
        if w.laser.kind in ("line", "lines") and w.board is None:
            exposure_ms = t.exposure_s(w.laser.lines, exposure_ms, w.laser.speed_mm_s) * 1e3
        seconds = t.frame_s(exposure_ms, w.laser.setup_s, t.readout_s(rows, cols))
        w.laser.setup_s = 0.0
        w.clock.advance("frames", seconds)


class SimScanHead:
    """Projects scan lines (one, or several in one exposure) and the pilot spot on the
    world; its moves set the next frame's timing (the jump to the list's start, the speed
    its lines are swept at: :class:`~insitu.sim.clock.SimTiming`)."""

    def __init__(self, world: SimWorld):
        self.world = world
        nominal = world.rig.operator.head
        self.field_size_mm = tuple(nominal.field_size_mm)
        self.z_range_mm = tuple(nominal.z_range_mm)
        self.speed_mm_s = world.timing.max_sweep_mm_s()

    def _check(self, *points) -> None:
        check_in_field(self.field_size_mm, *points)

    def set_line_speed(self, speed_mm_s: float) -> None:
        """How fast each line is swept (the frames' timing), at most the head's
        (:meth:`~insitu.sim.clock.SimTiming.max_sweep_mm_s`); the simulated picture of a
        line is the same at any speed (its light follows the exposure)."""
        top = self.world.timing.max_sweep_mm_s()
        if not 0 < speed_mm_s <= top:
            raise SafetyError(f"scan head: line speed {speed_mm_s:g} mm/s: expected > 0 and "
                              f"at most the head's {top:g} mm/s (rig file: "
                              "options.sim_timing.line_speed_mm_s)")
        self.speed_mm_s = float(speed_mm_s)

    def show_line(self, start, end, focus_z: float = 0.0) -> None:
        self.show_lines([(start, end)], focus_z)

    def show_lines(self, lines, focus_z: float = 0.0) -> None:
        """Draw ``lines`` ((start, end) mm on z = 0 each) in turn during each exposure, one
        list (one line: :meth:`show_line`)."""
        lines = [(np.asarray(a, float), np.asarray(b, float)) for a, b in lines]
        if not lines:
            raise SafetyError("scan head: no line to draw")
        self._check(*(p for line in lines for p in line))
        kind = "line" if len(lines) == 1 else "lines"
        self._set(LaserState(kind, lines[0][0], lines[0][1], float(focus_z), tuple(lines),
                             speed_mm_s=self.speed_mm_s))

    def show_spot(self, xy, focus_z: float = 0.0) -> None:
        self._check(xy)
        self._set(LaserState("spot", np.asarray(xy, float), None, float(focus_z)))

    def _set(self, laser: LaserState) -> None:
        """Show ``laser``, its list starting with a jump from where the last one left the
        head (several lines: the last one's end)."""
        w = self.world
        laser.setup_s = w.timing.jump_s(float(np.linalg.norm(laser.start - w.head_xy)))
        w.head_xy = (laser.lines[-1][1] if laser.kind == "lines" else laser.start).copy()
        w.laser = laser

    def off(self) -> None:
        self.world.laser = LaserState()


class SimStage:
    """Z stage carrying the calibration plate."""

    def __init__(self, world: SimWorld):
        self.world = world

    def move_z(self, z_mm: float) -> None:
        w = self.world
        w.clock.advance("stage", w.timing.stage_s(abs(float(z_mm) - (w.plate_z or 0.0))))
        w.plate_z = float(z_mm)
        w.invalidate()

    def position_z(self) -> float:
        return float(self.world.plate_z if self.world.plate_z is not None else np.nan)


class SimInspectionCamera(SimCamera):
    """The sim camera that also sees the marks: with the laser off, a frame of the (marked)
    part under room light (:func:`~insitu.sim.marks.render_inspection`). Its exposure, as a
    machine-vision camera's: automatic until :meth:`set_exposure` is called (room light then
    at ``inspection_exposure_ms``, laser frames at the nominal exposure), then that one
    exposure for every frame (as ``GenICamCamera.set_exposure`` turns ExposureAuto off).
    The ray cast of the camera's pixels is kept per scene: only the first room-light frame
    of a scene casts them."""

    def __init__(self, world: SimWorld, exposure_ms: float = 12 * NOMINAL_EXPOSURE_MS):
        super().__init__(world)
        self.inspection_exposure_ms = float(exposure_ms)
        self._manual = False
        self._frames = 0
        self._view: tuple[Scene, RoomLightView] | None = None

    def set_exposure(self, exposure_ms: float) -> None:
        super().set_exposure(exposure_ms)
        self._manual = True

    @property
    def room_light_exposure_ms(self) -> float:
        """The exposure of a frame with the laser off."""
        return self.exposure_ms if self._manual else self.inspection_exposure_ms

    def _render(self) -> np.ndarray:
        if self.world.laser.kind != "off" or self.world.board is not None:
            return super()._render()
        self._frames += 1
        scene = self.world.renderer().scene
        if self._view is None or self._view[0] is not scene:
            self._view = scene, RoomLightView(self.world.rig, scene)
        return render_inspection(self.world.rig, scene, list(self.world.burns),
                                 self.room_light_exposure_ms,
                                 seed=self.world.seed + self._frames, view=self._view[1])

    def _exposure_now_ms(self) -> float:
        laser_off = self.world.laser.kind == "off" and self.world.board is None
        return self.room_light_exposure_ms if laser_off else self.exposure_ms


def sim_devices(world: SimWorld) -> Devices:
    """The simulated station's devices, all on ``world``: the camera that also images marks,
    the head projecting scan lines, the marking controller and the plate's Z stage."""
    return Devices(SimInspectionCamera(world), SimScanHead(world), SimController(world),
                   SimStage(world))
