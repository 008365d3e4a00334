"""The frames of a scan on the station: each drawn (its lines back and forth), exposed for
its lines, taken by the camera reading only where the lines can be; the survey frames that
bound the heights before lines are packed (:mod:`insitu.reconstruct.packing`)."""

from __future__ import annotations

import queue
import threading

import numpy as np

from insitu.devices.protocols import Camera, ExposureCamera, RoiCamera, ScanHead
from insitu.errors import DeviceError
from insitu.reconstruct.packing import Frame
from insitu.reconstruct.plane import band_and_side, line_runs_along_rows
from insitu.reconstruct.scan import ExcessLight, ScanReconstructor, excess_room_light


class ScanInterrupted(DeviceError):
    """A device failed mid-scan; the laser is off. ``partial``: the result of the lines
    measured before the fault (None when none gave points)."""

    def __init__(self, message: str, partial):
        super().__init__(message)
        self.partial = partial

def region_of_interest(rec: ScanReconstructor, lines) -> tuple[int, int, int, int] | None:
    """The pixels (u0, v0, u1, v1) every line's band (its search at the focus range) lies in;
    None when one reaches no pixel."""
    boxes = line_boxes(rec, lines)
    if boxes is None:
        return None
    u0, v0, u1, v1 = np.array(boxes).T
    return int(u0.min()), int(v0.min()), int(np.ceil(u1.max())), int(np.ceil(v1.max()))


def line_boxes(rec: ScanReconstructor, lines) -> list[tuple[float, ...]] | None:
    """Each line's band as a box (u0, v0, u1, v1) px; None when one reaches no pixel."""
    boxes = []
    for a, b in lines:
        rows = line_runs_along_rows(rec.camera, a, b)
        lo, hi, _ = band_and_side(rec.camera, a, b, rec.H, rec.z_range or (-25.0, 25.0),
                                  telecentric=rec.telecentric, along_rows=rows)
        ok = np.flatnonzero(np.isfinite(lo) & np.isfinite(hi))
        if not len(ok):
            return None
        across = (np.nanmin(lo), np.nanmax(hi) + 1)
        along = (ok[0], ok[-1] + 1)
        boxes.append((along[0], across[0], along[1], across[1]) if rows
                     else (across[0], along[0], across[1], along[1]))
    return boxes


def moving_window(rec: ScanReconstructor, frames: list[Frame], width: int, height: int
                  ) -> list[tuple[int, int, int, int]] | None:
    """A region of interest (u0, v0, u1, v1) px for each of ``frames``, all of one size (the
    largest of their bands' boxes) and each over its own frame's lines: a camera moves its
    region between frames without stopping when only its place changes (the frame's size
    stays). None when a line reaches no pixel."""
    boxes = []
    for f in frames:
        got = line_boxes(rec, f.lines)
        if got is None:
            return None
        b = np.array(got)
        boxes.append((b[:, 0].min(), b[:, 1].min(), b[:, 2].max(), b[:, 3].max()))
    b = np.array(boxes)
    cols = min(int(np.ceil((b[:, 2] - b[:, 0]).max())) + 16, width)
    rows = min(int(np.ceil((b[:, 3] - b[:, 1]).max())) + 2, height)
    out = []
    for u0, v0, _, _ in b:
        u = int(np.clip(np.floor(u0 / 16) * 16, 0, width - cols))
        v = int(np.clip(np.floor(v0 / 2) * 2, 0, height - rows))
        out.append((u, v, u + cols, v + rows))
    return out


class Shots:
    """Frames of a scan's lines: the head draws a frame's lines, the camera (reading
    ``roi``, when it can) takes them, exposed as long as each line alone times their count
    (a camera that says its exposure); :meth:`done` turns the laser off and sets the camera
    back."""

    def __init__(self, camera: Camera, head: ScanHead, roi):
        self.camera, self.head = camera, head
        self.base = camera.exposure_ms if isinstance(camera, ExposureCamera) else None
        self.roi = roi if isinstance(camera, RoiCamera) else None
        self.windows: list | None = None
        self._roi_set = None
        self._at = None                 # where the last frame's lines left the head, mm

    def follow(self, windows: list | None) -> None:
        """From now on frame i is read in ``windows[i]`` (:func:`moving_window`; None: the
        whole scan's region)."""
        if self.roi is not None:
            self.windows = windows

    def _expose(self, k: int, i: int | None = None) -> None:
        """The region of interest set (frame ``i``'s window, when it has one), the exposure
        of a frame of ``k`` lines."""
        roi = self.roi if self.windows is None or i is None else self.windows[i]
        if roi is not None and roi != self._roi_set:
            self.camera.set_region_of_interest(roi)
            self._roi_set = roi
        if self.base is not None:
            want = self.base * k
            if self.camera.exposure_ms != want:
                self.camera.set_exposure(want)

    def laser_off(self, k: int) -> np.ndarray | None:
        """A frame with the laser off, exposed as a frame of ``k`` lines (None: the camera
        does not say its exposure, so frames of several lines are not exposed longer)."""
        if self.base is None:
            return None
        try:
            self.head.off()
            self._expose(k)
            return self.camera.grab()
        except DeviceError as e:
            self.head.off()
            raise ScanInterrupted(f"scan stopped at the laser-off frame of {k} lines' "
                                  f"exposure, laser off: {e}", None) from e

    def take(self, frame: Frame, i: int, n: int, partial) -> np.ndarray:
        try:
            self._expose(len(frame.lines), i)
            if len(frame.lines) == 1:
                self.head.show_line(*frame.lines[0])
                self._at = frame.lines[0][0]
            else:
                drawn = drawing_order(frame.lines, self._at)
                self.head.show_lines(drawn)
                self._at = drawn[-1][1]
            return self.camera.grab()
        except DeviceError as e:
            self.head.off()
            what = "line" if len(frame.lines) == 1 else "frame"
            raise ScanInterrupted(f"scan stopped at {what} {i + 1} of {n}, laser off: {e}",
                                  partial()) from e

    def done(self) -> None:
        self.head.off()
        if self._roi_set is not None:
            self.camera.set_region_of_interest(None)
        if self.base is not None and self.camera.exposure_ms != self.base:
            self.camera.set_exposure(self.base)


class Stream:
    """The ``frames`` taken by ``shot`` on a thread of their own, the next ones while the
    caller processes the last (at most ``depth`` waiting): iterate for (index, frame, image);
    a device fault comes out as the :class:`ScanInterrupted` it raised (the laser off, no
    partial result: the caller has it). :meth:`close` stops the taking and waits for it."""

    def __init__(self, shot: Shots, frames: list[Frame], depth: int = 2):
        self.shot, self.frames = shot, frames
        self._items: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._take, name="scan frames", daemon=True)
        self._thread.start()

    def _take(self) -> None:
        try:
            for i, f in enumerate(self.frames):
                if self._stop.is_set():
                    return
                self._put((i, f, self.shot.take(f, i, len(self.frames), lambda: None)))
        except BaseException as e:     # handed to the caller's thread, raised there
            self._put(e)
        else:
            self._put(None)

    def _put(self, item) -> None:
        while not self._stop.is_set():
            try:
                self._items.put(item, timeout=0.05)
                return
            except queue.Full:
                continue

    def __iter__(self):
        while True:
            item = self._items.get()
            if item is None:
                return
            if isinstance(item, BaseException):
                raise item
            yield item

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def back_and_forth(lines) -> list:
    """``lines`` ((start, end) each) with every second one drawn end → start: the head's
    jump between two lines is then across them, not back along them (the same lines)."""
    return [(a, b) if k % 2 == 0 else (b, a) for k, (a, b) in enumerate(lines)]


def drawing_order(lines, at=None) -> list:
    """``lines`` ((start, end) mm each) as the head draws them in one exposure: back and
    forth, from whichever end of the first or the last line lies nearest ``at`` (x, y mm:
    where the head is; None: the first line's start). The same lines, in the same exposure:
    only the head's jump to them is shorter."""
    ways = [back_and_forth(lines), back_and_forth(list(lines)[::-1])]
    ways += [[(b, a) for a, b in w] for w in ways]
    if at is None:
        return ways[0]
    return min(ways, key=lambda w: float(np.linalg.norm(np.subtract(w[0][0], at))))


def laser_off_frames(shot: Shots, frames: list[Frame]) -> dict[int, np.ndarray]:
    """For each count K > 1 of lines in the packed ``frames``: one frame with the laser off
    at their exposure, taken now (K → the frame); empty when the camera does not say its
    exposure (a recording's: its own laser-off frames, :func:`recorded_excess`)."""
    out: dict[int, np.ndarray] = {}
    for k in sorted({len(f.lines) for f in frames if not f.survey and len(f.lines) > 1}):
        image = shot.laser_off(k)
        if image is None:
            return {}
        out[k] = image
    return out


def recorded_excess(seq) -> dict[int, ExcessLight]:
    """A recording's (:class:`~insitu.formats.sequence.Sequence`) laser-off frames as the
    :func:`~insitu.reconstruct.scan.excess_room_light` of the packed frames of the same
    exposure (K lines → its (K − 1)/K); none for frames without an exposure."""
    out: dict[int, ExcessLight] = {}
    for i, off in enumerate(seq.laser_off):
        ks = {len(f.drawn()) for f in seq.frames if not f.survey and len(f.drawn()) > 1
              and f.exposure_ms is not None and off.exposure_ms is not None
              and abs(f.exposure_ms - off.exposure_ms) <= 1e-6 * off.exposure_ms}
        out |= {k: excess_room_light(seq.read_laser_off(i), k) for k in ks}
    return out


def describe_packing(plan, frames: list[Frame], measured) -> str:
    """How the scan's frames were packed, one line of text."""
    most = max((len(f.lines) for f in frames if not f.survey), default=1)
    if most == 1 and not plan.packed:
        return "one line a frame"
    lo, hi = plan.z_range
    source = ("known" if plan.heights is not None else "the survey frame's" if measured
              else "the focus range (no survey)")
    gap = f", ≥ {plan.gap_mm:.1f} mm apart" if plan.gap_mm is not None else ""
    return (f"up to {most} lines a frame{gap}; bands for heights {lo:.1f} … {hi:.1f} mm "
            f"({source})")


def survey_heights(shot: Shots, rec: ScanReconstructor, plan, keep=None
                   ) -> tuple[tuple[float, float] | None, int]:
    """The plan's survey frames taken and measured (on a twin of ``rec``: their points are
    not the scan's; ``keep(frame, image)`` sees each): (the heights they saw, low and high
    mm, None: none; the frames taken)."""
    frames = plan.surveys()
    if not frames:
        return None, 0
    survey = rec.twin()
    for k, f in enumerate(frames):
        image = shot.take(f, k, len(frames), lambda: None)
        if keep is not None:
            keep(f, image)
        survey.add_lines(image, f.lines, f.ids, plan.focus_range, plan.packing)
    return survey.heights(), len(frames)


