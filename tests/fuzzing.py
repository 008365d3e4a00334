"""The fuzzing engine of every reader: mutated valid files, each example in a worker process
that catches hangs and crashes (tests/unit/test_fuzz_readers.py runs a few hundred examples,
benchmarks/fuzz.py thousands).

Each reader gets a valid seed file (tests/fuzz_seeds.py: PLY ascii and binary, a recording's
sequence.json and its PNG frame, rig file, height calibration, field correction, job, project,
pens, SVG, DXF). Every example mutates it — bytes flipped, truncated, deleted, duplicated; a
JSON field replaced by an extreme, non-finite, negative, huge or mistyped value, wrapped,
stringified or deleted; a number of a text format replaced; a PNG header's size changed — and
feeds it to the reader and the first use of what it read. Success or an ``insitu.errors`` error
in one line is fine; anything else is a failure. An example that takes longer than the timeout
is a hang (the worker is killed and restarted after it), one that kills the worker a crash.
"""

from __future__ import annotations

import json
import math
import multiprocessing as mp
import random
import re
import shutil
import struct
import tempfile
import time
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from fuzz_seeds import READERS
from insitu.errors import InsituError

JSON_EXTREMES = [float("nan"), float("inf"), -float("inf"), -1, 0, -5, 4e9, 1e308, -1e308,
                 1e-300, 1e-320, 10**30, -(10**30), 2**63, 0.5, "", "x" * 5000, "/dev/zero",
                 "nan", None, True, False, [], {}, [[[[[1]]]]], [0] * 1000, {"a": {"b": []}}]
TEXT_EXTREMES = ["nan", "inf", "-inf", "1e400", "-1e400", "-1", "0", "-5", "4000000000", "4e9",
                 "1e308", "-1e308", "1e-320", "1e-300", "abc", "", "99999999999999999999",
                 "0x10", "1.5", "-0", "1e9", "65536"]
_NUMBER = re.compile(rb"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")


# -------------------------------------------------------------------------- mutations
def _bytes(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    b = bytearray(data)
    op = rng.choice(["flip", "truncate", "delete", "duplicate", "insert"])
    if not b:
        return bytes(rng.randrange(256) for _ in range(8)), "random bytes"
    i = rng.randrange(len(b))
    if op == "flip":
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif op == "truncate":
        del b[i:]
    elif op == "delete":
        del b[i:i + rng.randint(1, 64)]
    elif op == "duplicate":
        b[i:i] = b[i:i + rng.randint(1, 256)] * rng.randint(1, 50)
    else:
        b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    return bytes(b), f"bytes {op} at {i}"


def _key_paths(value, prefix=()):
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _key_paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value[:4]):
            yield from _key_paths(v, prefix + (i,))


def _json(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    value = json.loads(data)
    where = rng.choice(list(_key_paths(value))[1:] or [()])
    op = rng.choice(["extreme", "extreme", "extreme", "delete", "wrap", "string", "scale"])
    if not where:
        return json.dumps(rng.choice(JSON_EXTREMES)).encode(), "whole file replaced"
    parent = value
    for k in where[:-1]:
        parent = parent[k]
    key, old = where[-1], parent[where[-1]]
    if op == "delete":
        del parent[key]
    elif op == "wrap":
        parent[key] = [old]
    elif op == "string":
        parent[key] = json.dumps(old) if not isinstance(old, str) else rng.choice([1, [old]])
    elif op == "scale" and isinstance(old, (int, float)) and not isinstance(old, bool):
        parent[key] = old * rng.choice([-1, 1e6, 1e-6, 1e300, 0])
    else:
        parent[key] = rng.choice(JSON_EXTREMES)
    return json.dumps(value).encode(), f"json {op} {'.'.join(map(str, where))}"


def _text(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    spans = [m.span() for m in _NUMBER.finditer(data)]
    if not spans or rng.random() < 0.25:
        return _bytes(data, rng)
    out = bytearray(data)
    picks = sorted(rng.sample(spans, min(len(spans), rng.randint(1, 3))), reverse=True)
    for a, b in picks:
        out[a:b] = rng.choice(TEXT_EXTREMES).encode()
    return bytes(out), f"numbers at {[a for a, _ in picks]} replaced"


def _ply(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    end = data.find(b"end_header\n") + 11
    r = rng.random()
    if r < 0.4:
        head, how = _text(data[:end], rng)
        return head + data[end:], "header " + how
    if r < 0.6 and len(data) >= end + 8:
        i = rng.randrange(end, len(data) - 7)
        v = rng.choice([math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0])
        return data[:i] + struct.pack("<d", v) + data[i + 8:], f"double {v} at {i}"
    return _bytes(data, rng)


def _png(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    if rng.random() < 0.5:
        return _bytes(data, rng)
    w, h = rng.choice([0, 1, 31, 33, 20000, 65535, 2**31 - 1]), rng.choice([0, 1, 23, 20000])
    b = bytearray(data)
    b[16:24] = struct.pack(">II", w, h)
    if rng.random() < 0.8:                       # a valid CRC, so the header itself parses
        b[29:33] = struct.pack(">I", zlib.crc32(bytes(b[12:29])))
    return bytes(b), f"IHDR {w}x{h}"


MUTATE = {"bytes": _bytes, "json": _json, "text": _text, "ply": _ply, "png": _png}


def example(name: str, valid: bytes, seed: int, i: int) -> tuple[bytes, str]:
    """Example ``i`` of reader ``name`` (the same for the same seed): (content, how made)."""
    rng = random.Random(f"{seed}:{name}:{i}")
    return MUTATE[READERS[name][1]](valid, rng)


# -------------------------------------------------------------------------- running
def _worker(conn, name: str, seed: int, start: int, stop: int) -> None:
    warnings.simplefilter("ignore")
    folder = Path(tempfile.mkdtemp(prefix=f"insitu-fuzz-{name}-"))
    try:
        target, read = READERS[name][0](folder)
        valid = target.read_bytes()
        read(target)                                     # the seed itself reads cleanly
        for i in range(start, stop):
            data, how = example(name, valid, seed, i)
            target.write_bytes(data)
            conn.send(("start", i, how))
            t = time.perf_counter()
            try:
                read(target)
                res, detail = "ok", ""
            except InsituError as e:
                msg = str(e)
                res, detail = ("refused", msg) if msg and "\n" not in msg else (
                    "failure", f"not one line: {msg!r}")
            except (Exception, SystemExit) as e:  # noqa: BLE001 — the point: report it
                res, detail = "failure", f"{type(e).__name__}: {' '.join(str(e).split())[:200]}"
            conn.send(("done", i, res, 1e3 * (time.perf_counter() - t), detail))
        conn.send(("end",))
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@dataclass
class Stats:
    """The outcome of one reader's examples; ``failures``: (index, how made, what happened)."""

    name: str
    examples: int = 0
    ok: int = 0
    refused: int = 0
    hangs: int = 0
    max_ms: float = 0.0
    slowest: tuple[int, str] = (-1, "")
    total_ms: float = 0.0
    failures: list[tuple[int, str, str]] = field(default_factory=list)


def run_reader(name: str, seed: int, n: int, timeout_s: float = 10.0, start: int = 0) -> Stats:
    """Examples ``start`` … ``start + n - 1`` of reader ``name`` in worker processes."""
    ctx = mp.get_context("fork")
    st, i, stop = Stats(name), start, start + n
    while i < stop:
        recv, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_worker, args=(send, name, seed, i, stop), daemon=True)
        proc.start()
        send.close()
        current, how, finished = None, "seed file", False
        while True:
            if not recv.poll(timeout_s if current is not None else 300.0):
                proc.kill()
                what = f"hang (> {timeout_s:g} s)"
            else:
                try:
                    msg = recv.recv()
                except EOFError:
                    proc.join(5)
                    msg, what = None, f"crash (worker exit code {proc.exitcode})"
                if msg is not None and msg[0] == "start":
                    current, how = msg[1], msg[2]
                    continue
                if msg is not None and msg[0] == "done":
                    _, k, res, ms, detail = msg
                    st.examples += 1
                    if ms > st.max_ms:
                        st.max_ms, st.slowest = ms, (k, how)
                    st.total_ms += ms
                    if res == "ok":
                        st.ok += 1
                    elif res == "refused":
                        st.refused += 1
                    else:
                        st.failures.append((k, how, detail))
                    current, i = None, k + 1
                    continue
                finished = msg is not None                   # ("end",)
            if not finished:                                 # a hang or a crash
                st.examples, st.hangs = st.examples + 1, st.hangs + 1
                st.failures.append((-1 if current is None else current, how, what))
            break
        proc.join(5)
        recv.close()
        if finished or current is None:          # done, or the seed itself did not read
            break
        i = current + 1
    return st
