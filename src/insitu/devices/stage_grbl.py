"""Z stage on a serial G-code controller speaking GRBL (1.1, and 0.9 status reports), via
pyserial: homing, absolute moves in mm, position read-back, alarms as DeviceError.

World z = machine position of ``axis`` × ``sign`` + ``offset_mm`` (set in the rig file after
homing: the plate top's height when the machine reads 0). GRBL answers every line with
``ok`` or ``error:N``; ``ALARM:N`` arrives unprompted; ``?`` is answered at once with a status
report ``<Idle|MPos:x,y,z|…>``. A move is done when the report says Idle at the target.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable

import serial

from insitu.errors import ConfigError, DeviceError
from insitu.formats.bounds import check

ALARMS = {1: "hard limit triggered", 2: "soft limit: target outside the travel",
          3: "reset while in motion (position lost; home again)", 4: "probe fail",
          5: "probe fail", 6: "homing fail: reset during homing",
          7: "homing fail: door opened during homing",
          8: "homing fail: pull-off did not clear the limit switch",
          9: "homing fail: limit switch not found", 10: "homing fail: second switch"}
ERRORS = {1: "G-code word without a letter", 2: "bad number", 3: "'$' command not recognised",
          8: "command only valid when Idle", 9: "G-code locked out during alarm or jog",
          15: "jog target exceeds travel", 20: "unsupported G-code command",
          22: "feed rate not set"}
_STATUS = re.compile(r"<([A-Za-z]+)(?::\d+)?[|,](.*)>")


def parse_status(line: str) -> tuple[str, dict[str, list[float]]]:
    """``<Idle|MPos:0.000,0.000,5.000|FS:0,0>`` → ("Idle", {"MPos": [0, 0, 5], "FS": [0, 0]}).
    Also GRBL 0.9's ``<Idle,MPos:…,WPos:…>``. DeviceError if it is no status report."""
    m = _STATUS.fullmatch(line.strip())
    if not m:
        raise DeviceError(f"GRBL stage: not a status report: {line.strip()[:80]!r}")
    fields: dict[str, list[float]] = {}
    for part in re.split(r"[|,](?=[A-Za-z]+:)", m.group(2)):
        key, _, vals = part.partition(":")
        try:
            fields[key] = [float(v) for v in vals.split(",") if v]
        except ValueError:
            continue
    return m.group(1), fields


class GrblStage:
    """A :class:`~insitu.devices.protocols.Stage`. ``port``: a pyserial URL or device
    (``/dev/ttyUSB0``, ``COM3``); ``z_range_mm``: allowed world heights (moves outside are
    refused before anything is sent); ``feed_mm_min``: move speed; ``timeout_s``: for a move or
    homing; ``reply_timeout_s``: for any other answer."""

    def __init__(self, port: str, baudrate: int = 115200, axis: str = "Z", sign: float = 1.0,
                 offset_mm: float = 0.0, feed_mm_min: float = 300.0,
                 z_range_mm: tuple[float, float] = (-50.0, 50.0), timeout_s: float = 60.0,
                 home_on_open: bool = False, poll_s: float = 0.05, reply_timeout_s: float = 3.0,
                 open_port: Callable[..., serial.SerialBase] = serial.serial_for_url):
        axis = axis.upper()
        if axis not in "XYZ" or len(axis) != 1:
            raise ConfigError(f"options.stage.axis: expected X, Y or Z, got {axis!r}")
        for key, bound, value in (("offset_mm", "position_mm", offset_mm),
                                  ("feed_mm_min", "feed_mm_min", feed_mm_min),
                                  ("z_range_mm[0]", "position_mm", z_range_mm[0]),
                                  ("z_range_mm[1]", "position_mm", z_range_mm[1]),
                                  ("timeout_s", "timeout_s", timeout_s)):
            check(bound, value, f"options.stage.{key}", ConfigError)
        self.axis, self.index = axis, "XYZ".index(axis)
        self.sign, self.offset_mm, self.feed = float(sign), float(offset_mm), float(feed_mm_min)
        self.z_range_mm, self.timeout_s, self.poll_s = tuple(z_range_mm), timeout_s, poll_s
        self.reply_timeout_s = float(reply_timeout_s)
        self.port_name = port
        try:
            self.ser = open_port(port, baudrate=baudrate, timeout=0.05)
        except (serial.SerialException, OSError, ValueError) as e:
            raise DeviceError(f"GRBL stage: cannot open {port} ({e})") from None
        self._reset()
        self._command("G21 G90")                # mm, absolute
        if home_on_open:
            self.home()

    # -- protocol -----------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        try:
            self.ser.write(data)
            self.ser.flush()
        except (serial.SerialException, OSError) as e:
            raise DeviceError(f"GRBL stage on {self.port_name}: write failed ({e})") from None

    def _readline(self, deadline: float, waiting_for: str) -> str:
        buf = b""
        while True:
            try:
                buf += self.ser.read_until(b"\n")
            except (serial.SerialException, OSError) as e:
                raise DeviceError(f"GRBL stage on {self.port_name}: read failed ({e}); "
                                  "cable unplugged?") from None
            if buf.endswith(b"\n"):
                return buf.decode("ascii", "replace").strip()
            if time.monotonic() > deadline:
                raise DeviceError(f"GRBL stage on {self.port_name}: no answer to "
                                  f"{waiting_for} within the timeout")

    def _reset(self) -> None:
        """Soft reset (Ctrl-X) and wait for the ``Grbl …`` banner."""
        self.ser.reset_input_buffer()
        self._write(b"\x18")
        deadline = time.monotonic() + self.reply_timeout_s
        while True:
            line = self._readline(deadline, "a reset (is a GRBL controller on this port?)")
            if line.startswith("Grbl"):
                self.version = line
                return

    def _command(self, line: str, timeout_s: float | None = None) -> None:
        """Send one line and wait for ``ok``; DeviceError on ``error:N`` or ``ALARM:N``."""
        self._write(line.encode("ascii") + b"\n")
        deadline = time.monotonic() + (timeout_s or self.reply_timeout_s)
        while True:
            reply = self._readline(deadline, repr(line))
            if reply == "ok":
                return
            self._raise_on(reply, line)

    def _raise_on(self, reply: str, line: str) -> None:
        if reply.startswith("error:"):
            code = int(reply[6:]) if reply[6:].isdigit() else -1
            raise DeviceError(f"GRBL stage: {line!r} refused: {ERRORS.get(code, reply)}")
        if reply.startswith("ALARM:"):
            code = int(reply[6:]) if reply[6:].isdigit() else -1
            raise DeviceError(f"GRBL stage alarm {code}: {ALARMS.get(code, 'unknown')}; "
                              "the stage is stopped (home it, or unlock with $X)")

    def status(self) -> tuple[str, float]:
        """(state, machine position of the axis, mm)."""
        self._write(b"?")
        deadline = time.monotonic() + self.reply_timeout_s
        while True:
            line = self._readline(deadline, "a status query")
            if line.startswith("<"):
                state, fields = parse_status(line)
                pos = fields.get("MPos") or fields.get("WPos")
                if pos is None or len(pos) <= self.index:
                    raise DeviceError(f"GRBL stage: status report without a position: {line}")
                if state == "Alarm":
                    raise DeviceError("GRBL stage is in alarm; the stage is stopped "
                                      "(home it, or unlock with $X)")
                return state, pos[self.index]
            self._raise_on(line, "?")

    # -- Stage --------------------------------------------------------------------------------
    def home(self) -> None:
        """Run the homing cycle ($H) and wait until it is done."""
        self._command("$H", timeout_s=self.timeout_s)

    def move_z(self, z_mm: float) -> None:
        lo, hi = self.z_range_mm
        if not lo <= z_mm <= hi:
            raise DeviceError(f"GRBL stage: z = {z_mm:g} mm is outside the stage range "
                              f"[{lo:g}, {hi:g}] mm")
        target = (float(z_mm) - self.offset_mm) / self.sign
        self._command(f"G1 {self.axis}{target:.4f} F{self.feed:.1f}")
        deadline = time.monotonic() + self.timeout_s
        while True:
            state, pos = self.status()
            if state == "Idle" and abs(pos - target) < 1e-3:
                return
            if time.monotonic() > deadline:
                raise DeviceError(f"GRBL stage: did not reach z = {z_mm:g} mm within "
                                  f"{self.timeout_s:g} s (at {pos * self.sign + self.offset_mm:g})")
            time.sleep(self.poll_s)

    def position_z(self) -> float:
        return self.status()[1] * self.sign + self.offset_mm

    def stop(self) -> None:
        """Feed hold then soft reset: stops at once. Never raises."""
        try:
            self.ser.write(b"!")
            self.ser.write(b"\x18")
        except Exception:                              # noqa: BLE001
            pass

    def close(self) -> None:
        self.ser.close()
