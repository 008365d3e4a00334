"""JCZ / BJJCZ LMC fibre-laser controller boards (EZCAD2's) over their USB protocol, with
pyusb; the protocol as MeerK40t's balormk / galvoplotter speak it.

USB 0x9588:0x9899, bulk out 0x02, bulk in 0x88. A *single command* is 12 bytes, six uint16
little-endian (opcode, five parameters), answered with 8 bytes (four uint16; the last is the
status: 0x20 ready, 0x04 busy). A *list* is sent in packets of 0xC00 bytes (256 twelve-byte
list commands, padded with end-of-list 0x8002), not answered; ``SetEndOfList`` after each
packet, ``ExecuteList`` to run, then poll status until not busy.

Units are converted here: mirror angles → 16-bit galvo values, 0x8000 at the centre,
``bits_per_deg`` per degree of mechanical angle (the board's correction table is the blank
one, so it drives the mirrors linearly; insitu's own field correction is in the angles);
speeds mm/s → galvo units/ms (at the field centre); delays µs (sign flag 0x8000 for
negative), waits in 10 µs; power % → 12-bit current; frequency kHz → Q-switch period in
1/20 µs. The board has no wobble of its own: as EZCAD does, a wobble (``set_wobble``, for
the rest of its list) is traced in the list — each mark becomes short marks along the path
with a circle of the wobble's amplitude turning at its frequency, 16 per turn, at the mark
speed. The board has no dynamic-focus axis: a list whose focus shifts exceed
``focus_tolerance_mm`` is refused (SafetyError) before anything is sent.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import usb.core
import usb.util

from insitu.devices.galvo import Command, ListPosition, check_setting
from insitu.devices.watchdog import Heartbeat
from insitu.errors import ConfigError, DeviceError, SafetyError
from insitu.formats.bounds import check_fields
from insitu.geometry.beams import TwoMirrorHead

VENDOR, PRODUCT, EP_OUT, EP_IN = 0x9588, 0x9899, 0x02, 0x88
PACKET = 0xC00
READY, BUSY = 0x20, 0x04
# single commands
DISABLE_LASER, ENABLE_LASER, EXECUTE_LIST, GET_VERSION, GET_SERIAL = 0x02, 0x04, 0x05, 0x07, 0x09
RESET_LIST, SET_CONTROL_MODE, SET_DELAY_MODE, SET_END_OF_LIST = 0x12, 0x16, 0x17, 0x19
SET_LASER_MODE, SET_TIMING, STOP_EXECUTE, WRITE_PORT, WRITE_COR_TABLE = 0x1B, 0x1C, 0x1F, 0x21, 0x15
FIBER_SET_MO = 0x33
# list commands
L_JUMP, L_END, L_DELAY, L_MARK, L_JUMP_SPEED = 0x8001, 0x8002, 0x8004, 0x8005, 0x8006
L_ON_DELAY, L_OFF_DELAY, L_MARK_SPEED, L_JUMP_DELAY, L_POLY_DELAY = (0x8007, 0x8008, 0x800C,
                                                                     0x800D, 0x800F)
L_WRITE_PORT, L_CURRENT, L_QSWITCH, L_READY = 0x8011, 0x8012, 0x801B, 0x8051
WOBBLE_POINTS_MAX = 1_000_000      # list points of one wobbled mark (16 a turn)


@dataclass(frozen=True)
class LmcSettings:
    """From the rig file's ``options.lmc``. ``bits_per_deg``: galvo units per degree of
    mechanical mirror angle; ``laser_pin`` / ``pilot_pin``: output-port bits of the laser
    enable and the red pilot light; ``index``: which board when several are plugged in."""

    bits_per_deg: float
    index: int = 0
    laser_pin: int = 0
    pilot_pin: int = 8
    focus_tolerance_mm: float = 1.0
    usb_timeout_ms: int = 500
    timeout_s: float = 60.0
    heartbeat_s: float = 0.25

    def __post_init__(self):
        check_fields(self, _LMC_BOUNDS, "options.lmc", ConfigError)


_LMC_BOUNDS = {"bits_per_deg": "bits_per_deg", "index": "board_index", "laser_pin": "board_index",
               "pilot_pin": "board_index", "focus_tolerance_mm": "focus_tolerance_mm",
               "usb_timeout_ms": "usb_timeout_ms", "timeout_s": "timeout_s",
               "heartbeat_s": "heartbeat_s"}


def _delay(us: float) -> tuple[int, int]:
    """µs → (magnitude, sign flag)."""
    return min(int(round(abs(us))), 0xFFFF), 0x8000 if us < 0 else 0


class LmcListBuilder:
    """Command lists → LMC list commands ``[(opcode, p1..p5)]``, remembering what the board
    is set to (delays are sent when they change)."""

    def __init__(self, head: TwoMirrorHead, s: LmcSettings):
        self.s = s
        rad_per_mm = 1.0 / (2.0 * head.mirror_distance_mm)       # at the field centre
        self.units_per_mm = s.bits_per_deg * math.degrees(rad_per_mm)
        self._last = (0x8000, 0x8000)
        self._delays: dict[int, tuple] = {}
        self._mark_speed: float | None = None
        self._wobble = (0.0, 0.0)          # amplitude mm, Hz: for the list being built
        self._phase = 0.0                  # turns of the wobble so far

    def galvo(self, joint) -> tuple[int, int]:
        ax, ay, df = (float(v) for v in joint)
        if abs(df) > self.s.focus_tolerance_mm:
            raise SafetyError(f"LMC: the board has no dynamic focus; this job needs a focus "
                              f"shift of {df:+.3f} mm (tolerance ±{self.s.focus_tolerance_mm:g} "
                              "mm): mark it flat, or use an RTC head")
        x, y = (0x8000 + round(a * self.s.bits_per_deg) for a in (ax, ay))
        if not (0 <= x <= 0xFFFF and 0 <= y <= 0xFFFF):
            raise SafetyError(f"LMC: mirror angles ({ax:+.3f}°, {ay:+.3f}°) are outside the "
                              f"board's range ±{0x8000 / self.s.bits_per_deg:.2f}°")
        return x, y

    def _move(self, op: int, x: int, y: int) -> list[tuple]:
        if op == L_MARK and self._wobble[0] > 0 and self._wobble[1] > 0:
            return [self._to(op, *q) for q in self._wobbled(x, y)]
        return [self._to(op, x, y)]

    def _to(self, op: int, x: int, y: int) -> tuple:
        if not (0 <= x <= 0xFFFF and 0 <= y <= 0xFFFF):
            raise SafetyError(f"LMC: the wobble takes the mirrors to ({x}, {y}), outside the "
                              "board's 16-bit range")
        dist = min(int(math.hypot(x - self._last[0], y - self._last[1])), 0xFFFF)
        self._last = (x, y)
        return (op, x, y, 0, dist, 0)

    def _wobbled(self, x: int, y: int) -> list[tuple[int, int]]:
        """Galvo points of a mark from the last point to (x, y) with the wobble's circle."""
        if self._mark_speed is None:
            raise SafetyError("LMC: a wobble needs the mark speed, but the list sets none")
        amp_mm, hz = self._wobble
        (x0, y0), r = self._centre, amp_mm * self.units_per_mm
        length_mm = math.hypot(x - x0, y - y0) / self.units_per_mm
        turns = length_mm / self._mark_speed * hz
        n = max(int(math.ceil(turns * 16)), 1)
        if n > WOBBLE_POINTS_MAX:
            raise SafetyError(f"LMC: a wobble of {hz:g} Hz over {length_mm:.3g} mm at "
                              f"{self._mark_speed:g} mm/s needs {n:,} list points (at most "
                              f"{WOBBLE_POINTS_MAX:,} a mark): lower its frequency or mark faster")
        out = []
        for k in range(1, n + 1):
            t = k / n
            a = 2 * math.pi * (self._phase + t * turns)
            out.append((round(x0 + t * (x - x0) + r * math.cos(a)),
                        round(y0 + t * (y - y0) + r * math.sin(a))))
        self._phase = (self._phase + turns) % 1.0
        return out

    def speed(self, mm_s: float) -> int:
        return min(int(round(mm_s * self.units_per_mm / 1000.0)), 0xFFFF)

    def commands(self, commands: Sequence[Command]) -> tuple[list[tuple], bool]:
        """The list for ``commands`` and whether the marking laser is switched on. SafetyError
        for a focus shift beyond the tolerance, angles beyond the galvo range, a speed or
        frequency not > 0, a power outside 0 … 100 %."""
        waits = {"laser_on_delay": L_ON_DELAY, "laser_off_delay": L_OFF_DELAY,
                 "jump_delay": L_JUMP_DELAY, "polygon_delay": L_POLY_DELAY}
        longest = {op: 0.0 for op in waits}
        body: list[tuple] = []
        marking, port = False, 0
        self._wobble, self._phase, self._centre = (0.0, 0.0), 0.0, self._last
        for c in commands:
            op = c.op
            check_setting("LMC", c)
            if op in waits:
                longest[op] = max(longest[op], float(c.args[0]))
            elif op in ("jump_abs_3d", "mark_abs_3d"):
                x, y = self.galvo(c.args)
                body += self._move(L_JUMP if op == "jump_abs_3d" else L_MARK, x, y)
                self._centre = (x, y)
            elif op == "set_wobble":
                self._wobble = (float(c.args[0]), float(c.args[1]))
            elif op == "set_mark_speed":
                self._mark_speed = float(c.args[0])
                body.append((L_MARK_SPEED, self.speed(c.args[0]), 0, 0, 0, 0))
            elif op == "set_jump_speed":
                body.append((L_JUMP_SPEED, self.speed(c.args[0]), 0, 0, 0, 0))
            elif op == "set_power":
                body.append((L_CURRENT, min(max(round(c.args[0] * 0xFFF / 100.0), 0), 0xFFF),
                             0, 0, 0, 0))
            elif op == "set_frequency":
                body.append((L_QSWITCH, min(round(20000.0 / c.args[0]), 0xFFFF), 0, 0, 0, 0))
            elif op == "mark_delay":
                body.append((L_DELAY, min(round(c.args[0] / 10.0), 0xFFFF), 0, 0, 0, 0))
            elif op in ("pilot_on", "pilot_off"):
                port = (1 << self.s.pilot_pin) if op == "pilot_on" else 0
                body.append((L_WRITE_PORT, port, 0, 0, 0, 0))
            elif op == "laser_on":
                marking = True
            elif op != "laser_off":
                raise DeviceError(f"LMC: unknown command {op!r}")
        head = [(L_READY, 0, 0, 0, 0, 0)]
        for name, code in waits.items():
            args = _delay(longest[name])
            if self._delays.get(code) != args:
                self._delays[code] = args
                head.append((code, *args, 0, 0, 0))
        return head + body + [(L_END, 0, 0, 0, 0, 0)], marking

    def forget(self) -> None:
        self._delays.clear()
        self._mark_speed = None


def packets(entries: list[tuple]) -> list[bytes]:
    """List commands → 0xC00-byte packets padded with end-of-list commands."""
    out = []
    for i in range(0, len(entries), PACKET // 12):
        chunk = b"".join(struct.pack("<6H", *e) for e in entries[i:i + PACKET // 12])
        pad = struct.pack("<6H", L_END, 0, 0, 0, 0, 0)
        out.append(chunk + pad * ((PACKET - len(chunk)) // 12))
    return out


class LmcConnection:
    """The board on USB. ``backend``: a pyusb backend (None: libusb1 as pyusb finds it)."""

    def __init__(self, index: int = 0, timeout_ms: int = 500, backend=None):
        self.timeout_ms = timeout_ms
        try:
            found = list(usb.core.find(idVendor=VENDOR, idProduct=PRODUCT, find_all=True,
                                       backend=backend))
        except usb.core.NoBackendError:
            raise DeviceError("LMC: no USB backend (install libusb-1.0)") from None
        if len(found) <= index:
            raise DeviceError(f"LMC: no board {index} on USB (found {len(found)} with id "
                              f"{VENDOR:04x}:{PRODUCT:04x}); plugged in and powered?")
        self.dev = found[index]
        try:
            self.dev.set_configuration()
            usb.util.claim_interface(self.dev, 0)
        except usb.core.USBError as e:
            raise DeviceError(f"LMC: cannot claim the board ({e}); is EZCAD or another "
                              "program using it, or are USB permissions missing?") from None

    def write(self, data: bytes) -> None:
        try:
            self.dev.write(EP_OUT, data, self.timeout_ms)
        except usb.core.USBError as e:
            raise DeviceError(f"LMC: USB write failed ({e}); board unplugged?") from None

    def command(self, op: int, *params: int) -> tuple[int, int, int, int]:
        """A single command → its 8-byte answer as four uint16."""
        p = (list(params) + [0] * 5)[:5]
        self.write(struct.pack("<6H", op, *p))
        try:
            r = bytes(self.dev.read(EP_IN, 8, self.timeout_ms))
        except usb.core.USBError as e:
            raise DeviceError(f"LMC: USB read failed ({e}); board unplugged?") from None
        if len(r) != 8:
            raise DeviceError(f"LMC: short answer ({len(r)} bytes) to command 0x{op:04x}")
        return struct.unpack("<4H", r)

    def close(self) -> None:
        usb.util.dispose_resources(self.dev)


class LmcController:
    """A :class:`~insitu.devices.galvo.Controller` for an LMC board."""

    def __init__(self, head: TwoMirrorHead, settings: LmcSettings, backend=None,
                 poll_s: float = 0.002):
        self.s, self.poll_s = settings, poll_s
        self.builder = LmcListBuilder(head, settings)
        self.head = head
        self.usb = LmcConnection(settings.index, settings.usb_timeout_ms, backend)
        self._lock = threading.RLock()
        self._init_board()
        self.heartbeat = Heartbeat("LMC", self.status, self.laser_off, self._lock,
                                   settings.heartbeat_s, max(4 * settings.heartbeat_s, 1.0))
        self.heartbeat.start()

    def _init_board(self) -> None:
        u = self.usb
        self.serial = u.command(GET_SERIAL)
        self.version = u.command(GET_VERSION)
        for op, *p in ((STOP_EXECUTE,), (WRITE_COR_TABLE, 0), (ENABLE_LASER,),
                       (SET_CONTROL_MODE, 0), (SET_LASER_MODE, 1), (SET_DELAY_MODE, 1),
                       (SET_TIMING, 1), (FIBER_SET_MO, 0), (WRITE_PORT, 0)):
            u.command(op, *p)

    def status(self) -> int:
        return self.usb.command(GET_VERSION)[3]

    def check(self, lists: Sequence[Sequence[Command]]) -> None:
        """Every list through a fresh list builder, nothing sent (SafetyError as execute)."""
        builder = LmcListBuilder(self.head, self.s)
        for commands in lists:
            builder.commands(commands)

    def position(self) -> ListPosition | None:
        """None: insitu does not read the board's list position (a cut path is marked again
        or skipped, never continued)."""
        return None

    def execute(self, commands: Sequence[Command]) -> None:
        with self._lock:
            self.heartbeat.check()
            entries, marking = self.builder.commands(commands)
            try:
                self._run(entries, marking)
            except DeviceError as e:
                self.builder.forget()
                self.heartbeat.fail(str(e))
                raise

    def _wait(self, until, what: str) -> None:
        t_end = time.monotonic() + self.s.timeout_s
        while True:
            st = self.status()
            self.heartbeat.feed()
            if until(st):
                return
            if time.monotonic() > t_end:
                raise DeviceError(f"LMC: {what} within {self.s.timeout_s:g} s")
            time.sleep(self.poll_s)

    def _run(self, entries: list[tuple], marking: bool) -> None:
        u = self.usb
        u.command(RESET_LIST)
        laser_port = (1 << self.s.laser_pin) if marking else 0
        if marking:
            u.command(ENABLE_LASER)
        u.command(WRITE_PORT, laser_port)
        u.command(FIBER_SET_MO, int(marking))
        started = False
        for k, packet in enumerate(packets(entries)):
            self._wait(lambda st: st & READY, "the board was not ready for the next packet")
            u.write(packet)
            u.command(SET_END_OF_LIST, 0)
            if k == 2:                                  # stream long lists while they run
                u.command(EXECUTE_LIST)
                started = True
        if not started:
            u.command(EXECUTE_LIST)
        self._wait(lambda st: not st & BUSY, "the list did not finish")
        if marking:
            u.command(FIBER_SET_MO, 0)
            u.command(WRITE_PORT, 0)

    def laser_off(self) -> None:
        """Stop the list, close the fibre laser's MO, disable the laser, laser and pilot ports
        off. Never raises."""
        for op, *p in ((STOP_EXECUTE,), (FIBER_SET_MO, 0), (DISABLE_LASER,), (WRITE_PORT, 0)):
            try:
                self.usb.command(op, *p)
            except Exception:                           # noqa: BLE001 — keep switching off
                pass

    def close(self) -> None:
        self.heartbeat.stop()
        self.laser_off()
        self.usb.close()
