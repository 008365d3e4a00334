"""A GRBL 1.1 controller on the far end of a pseudo-terminal: a thread that reads G-code
lines and real-time bytes from the pty master and answers as GRBL does. Motion takes time
(``speed_mm_s`` in simulated seconds, advanced on every status query). Faults: :meth:`alarm`
(ALARM:N, state Alarm, lines refused with error:9 until $X or $H), ``silent`` (answers
nothing: a cable pulled out)."""

from __future__ import annotations

import os
import re
import select
import threading
import time


class GrblPeer:
    def __init__(self, speed_mm_s: float = 200.0, homing_s: float = 0.05):
        self.master, self.slave = os.openpty()
        self.port = os.ttyname(self.slave)
        self.pos = [0.0, 0.0, 0.0]
        self.target = list(self.pos)
        self.speed, self.homing_s = speed_mm_s, homing_s
        self.state = "Idle"
        self.silent = False
        self.lines: list[str] = []
        self.realtime: list[bytes] = []
        self._t = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        os.close(self.master)
        os.close(self.slave)

    def alarm(self, code: int = 1) -> None:
        self.state = "Alarm"
        self.target = list(self.pos)
        self._send(f"ALARM:{code}\r\n")

    # -- the controller ------------------------------------------------------------------------
    def _send(self, text: str) -> None:
        if not self.silent:
            os.write(self.master, text.encode())

    def _advance(self) -> None:
        now = time.monotonic()
        dt, self._t = now - self._t, now
        if self.state != "Run":
            return
        for i in range(3):
            d = self.target[i] - self.pos[i]
            step = self.speed * dt
            self.pos[i] = self.target[i] if abs(d) <= step else self.pos[i] + step * (d > 0 or -1)
        if self.pos == self.target:
            self.state = "Idle"

    def _run(self) -> None:
        buf = b""
        while not self._stop.is_set():
            r, _, _ = select.select([self.master], [], [], 0.02)
            if not r:
                continue
            try:
                data = os.read(self.master, 1024)
            except OSError:
                return
            for b in data:
                ch = bytes([b])
                if ch in (b"?", b"!", b"\x18"):
                    self.realtime.append(ch)
                    self._realtime(ch)
                elif ch == b"\n":
                    line, buf = buf.decode().strip(), b""
                    if line:
                        self.lines.append(line)
                        self._line(line)
                elif ch != b"\r":
                    buf += ch

    def _realtime(self, ch: bytes) -> None:
        self._advance()
        if ch == b"?":
            p = ",".join(f"{v:.3f}" for v in self.pos)
            self._send(f"<{self.state}|MPos:{p}|FS:0,0>\r\n")
        elif ch == b"!":
            self.target = list(self.pos)
            self.state = "Hold" if self.state == "Run" else self.state
        else:                                   # soft reset
            if self.state == "Run":
                self.state = "Alarm"
                self.target = list(self.pos)
            self._send("\r\nGrbl 1.1h ['$' for help]\r\n")

    def _line(self, line: str) -> None:
        self._advance()
        if line == "$X":
            self.state = "Idle"
            self._send("[MSG:Caution: Unlocked]\r\nok\r\n")
        elif line == "$H":
            time.sleep(self.homing_s)
            self.pos = [0.0, 0.0, 0.0]
            self.target = list(self.pos)
            self.state = "Idle"
            self._send("ok\r\n")
        elif self.state == "Alarm":
            self._send("error:9\r\n")
        elif re.fullmatch(r"(G\d+\s*)+", line):
            self._send("ok\r\n")
        elif m := re.fullmatch(r"G[01] ([XYZ])(-?\d+(?:\.\d*)?)(?: F(\d+(?:\.\d*)?))?", line):
            self.target["XYZ".index(m.group(1))] = float(m.group(2))
            self.state = "Run"
            self._send("ok\r\n")
        else:
            self._send("error:20\r\n")
