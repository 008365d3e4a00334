"""SCANLAB RTC5 / RTC6 scan-head controller through the vendor's DLL / shared library (ctypes).

Units are converted here and nowhere else. The driver's commands carry mirror angles and a
focus shift (:mod:`.galvo`); the RTC works in field coordinates through its own 3-D
correction file, so each command becomes the point where the nominal head focuses, in bits:
``(x, y, z) mm × k_bits_per_mm`` (z with ``kz_bits_per_mm``), 20-bit signed. Speeds mm/s →
bits/ms; laser on/off delays µs → ½ µs; scanner delays µs → 10 µs; frequency kHz → half
period in 1/64 µs; power % → 12-bit analog output 1. The pilot laser is a bit of the digital
output port (``pilot_bit``). The RTC applies its scanner delays itself (jump delay after
every jump, mark delay after every mark sequence, polygon delay at every vertex), so the
driver's explicit delays set them; the polygon delay is the largest of the list's corners.
A wobble is the board's own ``set_wobbel`` (amplitude in bits across and along the path, the
frequency in Hz), switched off again before a list that does not set it.

One command list = one RTC list (list 1): ``set_start_list(1)`` … ``set_end_of_list()``,
``execute_list(1)``, then ``get_status`` until not busy. The marking laser is enabled only
for lists that switch it on; :meth:`RtcController.laser_off` stops execution, disables the
laser and the pilot, without waiting for any lock.
"""

from __future__ import annotations

import ctypes
import os
import threading
import time
from collections.abc import Sequence
from ctypes import POINTER, c_char_p, c_double, c_int, c_uint
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from insitu.devices.galvo import Command, ListPosition, check_setting, focus_points, list_digest
from insitu.devices.native import allowed_library
from insitu.devices.watchdog import Heartbeat
from insitu.errors import ConfigError, DeviceError, SafetyError
from insitu.formats.bounds import check_fields
from insitu.geometry.beams import TwoMirrorHead

BITS_MAX = 2**19 - 1                 # 20-bit signed coordinates (RTC5 and RTC6)
DA_MAX = 4095                        # 12-bit analog outputs
ERROR_TEXT = {1: "no board found", 2: "access denied (board used by another program)",
              4: "command not forwarded", 8: "board does not respond",
              16: "invalid parameter", 32: "list busy", 64: "list command rejected",
              128: "command converted", 256: "DLL and board versions differ",
              512: "board firmware not loaded", 1024: "DLL version too old"}

_U, _I, _D, _S = c_uint, c_int, c_double, c_char_p
SIGNATURES: dict[str, tuple[list, type | None]] = {
    "select_rtc": ([_U], _U), "load_program_file": ([_S], _U),
    "load_correction_file": ([_S, _U, _U], _U), "select_cor_table": ([_U, _U], None),
    "get_last_error": ([], _U), "reset_error": ([_U], None),
    "set_laser_mode": ([_U], None), "set_laser_control": ([_U], None),
    "set_start_list": ([_U], None), "set_end_of_list": ([], None),
    "execute_list": ([_U], None), "get_status": ([POINTER(_U), POINTER(_U)], None),
    "stop_execution": ([], None), "enable_laser": ([], None), "disable_laser": ([], None),
    "write_io_port_mask": ([_U, _U], None), "write_io_port_mask_list": ([_U, _U], None),
    "write_da_1_list": ([_U], None), "set_laser_pulses": ([_U, _U], None),
    "set_laser_delays": ([_I, _U], None), "set_scanner_delays": ([_U, _U, _U], None),
    "set_jump_speed": ([_D], None), "set_mark_speed": ([_D], None),
    "set_wobbel": ([_U, _U, _D], None),
    "jump_abs_3d": ([_I, _I, _I], None), "mark_abs_3d": ([_I, _I, _I], None),
}


def error_text(code: int) -> str:
    """RTC error bits → words, e.g. 8 → "board does not respond"."""
    words = [t for bit, t in ERROR_TEXT.items() if code & bit]
    return ", ".join(words) or f"error code {code}"


@dataclass(frozen=True)
class RtcSettings:
    """From the rig file's ``options.rtc``. ``library``: the RTC DLL / .so; ``generation``:
    5 or 6; ``correction_file``: the head's 3-D .ct5 correction; ``k_bits_per_mm``: the
    calibration factor of that file (x, y; ``kz_bits_per_mm`` for z, default the same);
    ``program_dir``: folder of the board's firmware files (None: the library's folder)."""

    library: Path
    correction_file: Path
    k_bits_per_mm: float
    kz_bits_per_mm: float | None = None
    generation: int = 6
    card: int = 1
    correction_table: int = 1
    program_dir: Path | None = None
    laser_mode: int = 1
    pulse_length_us: float = 2.0
    pilot_bit: int = 0
    timeout_s: float = 30.0
    heartbeat_s: float = 0.25

    def __post_init__(self):
        check_fields(self, _RTC_BOUNDS, "options.rtc", ConfigError)

    @property
    def kz(self) -> float:
        return self.kz_bits_per_mm if self.kz_bits_per_mm is not None else self.k_bits_per_mm


_RTC_BOUNDS = {"k_bits_per_mm": "k_bits_per_mm", "kz_bits_per_mm": "k_bits_per_mm",
               "card": "board_index", "correction_table": "board_index",
               "laser_mode": "board_index", "pulse_length_us": "pulse_length_us",
               "pilot_bit": "board_index", "timeout_s": "timeout_s", "heartbeat_s": "heartbeat_s"}


class RtcListBuilder:
    """Command lists → RTC list calls ``[(function, args)]``, remembering what the board is
    set to so that delays are sent only when they change."""

    def __init__(self, head: TwoMirrorHead, settings: RtcSettings):
        self.head, self.s = head, settings
        self._delays: dict[str, tuple] = {}
        self._wobble_on = False
        self.origin: list[int] = []

    def bits(self, joint: np.ndarray) -> tuple[int, int, int]:
        """(3,) [alpha_x_deg, alpha_y_deg, focus_mm] → (x, y, z) bits of the focus point."""
        p = focus_points(self.head, np.asarray(joint, float))[0]
        b = np.rint(p * [self.s.k_bits_per_mm, self.s.k_bits_per_mm, self.s.kz])
        if not np.all(np.abs(b) <= BITS_MAX):
            raise SafetyError(f"RTC: point ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) mm is "
                              f"outside the board's ±{BITS_MAX} bit range at "
                              f"{self.s.k_bits_per_mm:g} bits/mm", where_mm=(p[0], p[1]))
        return int(b[0]), int(b[1]), int(b[2])

    def calls(self, commands: Sequence[Command]) -> tuple[list[tuple[str, tuple]], bool]:
        """The list calls for ``commands`` and whether the marking laser is switched on;
        ``origin`` becomes, for each call, the index of the command it comes from. SafetyError
        for a point outside the bit range, a speed or frequency not > 0, a power outside
        0 … 100 %."""
        waits = {op: 0.0 for op in ("laser_on_delay", "laser_off_delay", "jump_delay",
                                    "mark_delay", "polygon_delay")}
        out: list[tuple[str, tuple]] = []
        origin: list[int] = []
        marking = False
        k, pilot = self.s.k_bits_per_mm, 1 << self.s.pilot_bit
        for i, c in enumerate(commands):
            op = c.op
            check_setting("RTC", c)
            origin += [i - 1] * (len(out) - len(origin))
            if op in waits:
                waits[op] = max(waits[op], float(c.args[0]))
            elif op in ("jump_abs_3d", "mark_abs_3d"):
                out.append((op, self.bits(c.args)))
            elif op in ("set_mark_speed", "set_jump_speed"):
                out.append((op, (float(c.args[0]) * k / 1000.0,)))
            elif op == "set_power":
                out.append(("write_da_1_list", (_clip(c.args[0] / 100.0 * DA_MAX, DA_MAX),)))
            elif op == "set_frequency":
                half = 1000.0 / float(c.args[0]) / 2.0 * 64.0
                out.append(("set_laser_pulses", (int(round(half)),
                                                 int(round(self.s.pulse_length_us * 64.0)))))
            elif op in ("pilot_on", "pilot_off"):
                out.append(("write_io_port_mask_list", (pilot if op == "pilot_on" else 0, pilot)))
            elif op == "set_wobble":
                out.append(("set_wobbel", self.wobble(*c.args)))
            elif op == "laser_on":
                marking = True
            elif op != "laser_off":
                raise DeviceError(f"RTC: unknown command {op!r}")
        origin += [len(commands) - 1] * (len(out) - len(origin))
        head = []
        laser = (int(round(waits["laser_on_delay"] * 2)), int(round(waits["laser_off_delay"] * 2)))
        scanner = tuple(int(round(waits[w] / 10.0)) for w in
                        ("jump_delay", "mark_delay", "polygon_delay"))
        for name, args in (("set_laser_delays", laser), ("set_scanner_delays", scanner)):
            if self._delays.get(name) != args:
                self._delays[name] = args
                head.append((name, args))
        wobbles = [args for name, args in out if name == "set_wobbel"]
        if self._wobble_on and not wobbles:
            head.append(("set_wobbel", (0, 0, 0.0)))     # the last list's wobble: off
        self._wobble_on = any(a[0] > 0 and a[2] > 0 for a in wobbles)
        self.origin = [0] * len(head) + origin
        return head + out, marking

    def wobble(self, amplitude_mm: float, frequency_hz: float) -> tuple[int, int, float]:
        """(transversal, longitudinal bits, Hz) of a circular wobble; SafetyError beyond the
        board's bit range."""
        bits = int(round(amplitude_mm * self.s.k_bits_per_mm))
        if bits > BITS_MAX:
            raise SafetyError(f"RTC: wobble {amplitude_mm:g} mm is {bits} bits, beyond the "
                              f"board's {BITS_MAX} at {self.s.k_bits_per_mm:g} bits/mm")
        return bits, bits, float(frequency_hz)

    def forget(self) -> None:
        """The board's state is unknown (after a fault): send every setting again."""
        self._delays.clear()
        self._wobble_on = True

    def commands_done(self, pointer: int, n_commands: int) -> int:
        """The board's list pointer (calls executed) → commands of the list fully done."""
        return self.origin[pointer] if pointer < len(self.origin) else n_commands


def _clip(v: float, hi: int) -> int:
    return int(min(max(round(v), 0), hi))


class RtcLibrary:
    """The RTC DLL with declared ctypes signatures; every call is checked for existence.
    Loaded only if the station file allows it (:mod:`.native`)."""

    def __init__(self, path: Path, generation: int):
        if generation not in (5, 6):
            raise ConfigError(f"options.rtc.generation: expected 5 or 6, got {generation!r}")
        real = allowed_library(path, "options.rtc.library")   # the station's consent first
        try:
            loader = ctypes.WinDLL if os.name == "nt" else ctypes.CDLL   # __stdcall on Windows
            self.dll = loader(str(real))
        except OSError as e:
            raise DeviceError(f"RTC: cannot load the library {path} ({e})") from None
        sigs = dict(SIGNATURES)
        sigs[f"init_rtc{generation}_dll"] = ([], _U)
        sigs[f"free_rtc{generation}_dll"] = ([], None)
        self.generation = generation
        for name, (argtypes, restype) in sigs.items():
            try:
                fn = getattr(self.dll, name)
            except AttributeError:
                raise DeviceError(f"RTC: {path} has no function {name}: not an "
                                  f"RTC{generation} library") from None
            fn.argtypes, fn.restype = argtypes, restype
            setattr(self, name, fn)

    def init(self) -> int:
        return getattr(self, f"init_rtc{self.generation}_dll")()

    def free(self) -> None:
        getattr(self, f"free_rtc{self.generation}_dll")()

    def status(self) -> tuple[int, int]:
        """(busy, position) of the list being executed."""
        busy, pos = c_uint(0), c_uint(0)
        self.get_status(ctypes.byref(busy), ctypes.byref(pos))
        return busy.value, pos.value


class RtcController:
    """A :class:`~insitu.devices.galvo.Controller` for an RTC board. Opens, initialises and
    loads the correction file on construction; DeviceError if the board does not answer."""

    def __init__(self, head: TwoMirrorHead, settings: RtcSettings, poll_s: float = 0.002):
        self.s, self.poll_s = settings, float(poll_s)
        self.builder = RtcListBuilder(head, settings)
        self.head = head
        self._position: ListPosition | None = None
        self.lib = RtcLibrary(settings.library, settings.generation)
        self._lock = threading.RLock()
        self._open()
        self.heartbeat = Heartbeat("RTC", self._ping, self.laser_off, self._lock,
                                   settings.heartbeat_s, max(4 * settings.heartbeat_s, 1.0))
        self.heartbeat.start()

    def _open(self) -> None:
        lib, s = self.lib, self.s
        err = lib.init()
        if err:
            raise DeviceError(f"RTC{s.generation}: init failed: {error_text(err)}")
        if lib.select_rtc(s.card) != s.card:
            raise DeviceError(f"RTC{s.generation}: card {s.card} not found")
        lib.stop_execution()
        prog = str(s.program_dir or Path(s.library).parent).encode()
        if err := lib.load_program_file(prog):
            raise DeviceError(f"RTC: cannot load the board program from {prog.decode()}: "
                              f"{error_text(err)}")
        if err := lib.load_correction_file(str(s.correction_file).encode(),
                                           s.correction_table, 3):
            raise DeviceError(f"RTC: correction file {s.correction_file}: cannot load it "
                              f"(code {err})")
        lib.select_cor_table(s.correction_table, 0)
        lib.set_laser_mode(s.laser_mode)
        lib.set_laser_control(0)
        lib.disable_laser()
        lib.write_io_port_mask(0, 1 << s.pilot_bit)
        self._check("initialisation")

    def _check(self, where: str) -> None:
        err = self.lib.get_last_error()
        if err:
            self.lib.reset_error(err)
            raise DeviceError(f"RTC: {where}: {error_text(err)}")

    def _ping(self) -> None:
        self.lib.status()
        self._check("status")

    # -- Controller ---------------------------------------------------------------------------
    def check(self, lists: Sequence[Sequence[Command]]) -> None:
        """Every list through a fresh list builder, nothing sent (SafetyError as execute)."""
        builder = RtcListBuilder(self.head, self.s)
        for commands in lists:
            builder.calls(commands)

    def position(self) -> ListPosition | None:
        """The list pointer the board last reported, in commands of the last list."""
        return self._position

    def execute(self, commands: Sequence[Command]) -> None:
        with self._lock:
            self.heartbeat.check()
            calls, marking = self.builder.calls(commands)
            digest, n = list_digest(commands), len(commands)
            self._position = ListPosition(digest, 0)

            def at(pointer: int) -> None:
                self._position = ListPosition(digest, self.builder.commands_done(pointer, n))
            try:
                self._run(calls, marking, at)
            except DeviceError as e:
                self.builder.forget()
                self.heartbeat.fail(str(e))
                raise

    def _run(self, calls: list[tuple[str, tuple]], marking: bool, at) -> None:
        lib = self.lib
        lib.set_start_list(1)
        for name, args in calls:
            getattr(lib, name)(*args)
        lib.set_end_of_list()
        self._check("loading the list")
        if marking:
            lib.enable_laser()
        lib.execute_list(1)
        t_end = time.monotonic() + self.s.timeout_s
        while True:
            busy, pointer = lib.status()
            self._check("executing the list")
            at(pointer if busy else len(calls))
            self.heartbeat.feed()
            if not busy:
                return
            if time.monotonic() > t_end:
                raise DeviceError(f"RTC: the list did not finish within {self.s.timeout_s:g} s")
            time.sleep(self.poll_s)

    def laser_off(self) -> None:
        """Stop the list, disable the laser and the pilot. Never raises."""
        lib = self.lib
        for fn, args in ((lib.stop_execution, ()), (lib.disable_laser, ()),
                         (lib.write_io_port_mask, (0, 1 << self.s.pilot_bit))):
            try:
                fn(*args)
            except Exception:                        # noqa: BLE001 — keep switching off
                pass

    def close(self) -> None:
        self.heartbeat.stop()
        self.laser_off()
        self.lib.free()
