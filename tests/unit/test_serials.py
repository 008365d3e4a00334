"""Variable data: templates in a pattern's text, GS1 check digits, and the serial counter —
locked, fsynced, each serial handed out once even when processes race for it."""

import json
import multiprocessing
import threading
from datetime import datetime, timedelta, timezone

import pytest

from insitu.errors import FormatError
from insitu.formats.counter import KEEP, lock_path, locked, read_counter
from insitu.patterns import load_pattern
from insitu.patterns.fields import (
    Variables,
    parse_fields,
    render_spec,
    render_text,
    template_fields,
    uses_serial,
)
from insitu.patterns.gs1 import check_gtin, gtin_check_digit

NOW = datetime(2026, 3, 9, 7, 5, tzinfo=timezone(timedelta(hours=1)))
V = Variables(42, {"gtin": "09506000134352", "lot": "A7"}, NOW)


@pytest.mark.parametrize("text, rendered", [
    ("SN {serial:05d} {date:%Y-%m-%d}", "SN 00042 2026-03-09"),
    ("{serial}", "42"),
    ("(01){gtin}(21){serial}", "(01)09506000134352(21)42"),
    ("{time:%H%M} {time} {date}", "0705 07:05 2026-03-09"),
    ("{lot:>4}|{serial:x}", "  A7|2a"),
    ("{{serial}} {{", "{serial} {"),
    ("no fields", "no fields"),
])
def test_templates_render(text, rendered):
    assert render_text(text, V) == rendered


@pytest.mark.parametrize("text, message", [
    ("{gtinn}", "field {gtinn} has no value (give it a value: gtinn=VALUE)"),
    ("{serial:%Y}", "field {serial:%Y}: format spec '%Y' does not fit a serial number"),
    ("{lot:05d}", "field {lot:05d}: format spec '05d' does not fit a text field"),
    ("SN {serial", "expected '}' before end of string"),
    ("SN }", "Single '}' encountered"),
    ("{0}", "field {0}: expected a name"),
    ("{serial.real}", "field {serial.real}: expected a name"),
    ("{serial!r}", "field {serial!r}: conversions and nested fields are not supported"),
    ("{serial:{lot}}", "conversions and nested fields"),
])
def test_bad_templates_are_one_line_naming_the_field(text, message):
    with pytest.raises(FormatError) as e:
        render_text(text, V, "qr:'x'")
    assert message in str(e.value) and str(e.value).startswith("qr:'x': ")
    assert "\n" not in str(e.value)


def test_a_serial_is_needed_when_the_text_uses_one():
    with pytest.raises(FormatError, match=r"field \{serial:05d\} needs a serial number"):
        render_text("SN {serial:05d}", Variables(None, {}, NOW))
    assert render_text("{date}", Variables(None, {}, NOW)) == "2026-03-09"


def test_specs_render_their_text_only_and_keep_options():
    assert render_spec('qr:"SN {serial:04d}";ec=H;module=0.3', V) == 'qr:"SN 0042";ec=H;module=0.3'
    assert render_spec("text:{lot}-{serial};size=3", V) == 'text:"A7-42";size=3'
    assert render_spec('code128:"a;b {serial}"', V) == 'code128:"a;b 42"'
    assert render_spec("qr:plain", V) == "qr:plain"
    assert render_spec("fiducials:3x3", V) == "fiducials:3x3"
    assert render_spec("logo{serial}.svg", V) == "logo{serial}.svg"      # a file: no template
    assert template_fields('datamatrix:"(01){gtin}(21){serial}{gtin}"') == ("gtin", "serial")
    assert template_fields("qr:{{x}}") == () and not uses_serial("text:{date}")
    assert uses_serial('text:"SN {serial:05d}";size=2')
    # the rendered spec loads as the rendered text
    assert load_pattern(render_spec('qr:"{lot}{serial}";ec=H', V)).code.text == "A742"


def test_user_fields_from_the_command_line():
    assert parse_fields(["gtin=09506000134352", "note=a=b", "e="]) == {
        "gtin": "09506000134352", "note": "a=b", "e": ""}
    for items, message in ((["gtin"], "expected NAME=VALUE"), (["1x=2"], "expected NAME=VALUE"),
                           (["serial=5"], "{serial} is built in"),
                           (["a=1", "a=2"], "var a: given twice")):
        with pytest.raises(FormatError, match=message.replace("{", r"\{").replace("}", r"\}")):
            parse_fields(items)


def test_gtin_check_digit():
    assert gtin_check_digit("0950600013435") == 2 and gtin_check_digit("0950110153000") == 3
    check_gtin("(01)09506000134352(21)42", "dm")
    check_gtin("(21)12345", "dm")                                   # no GTIN: nothing to check
    with pytest.raises(FormatError, match=r"^dm: GTIN \(01\)09506000134353: wrong check digit 3 "
                                          r"\(expected 2\)$"):
        check_gtin("(01)09506000134353(21)1", "dm")
    with pytest.raises(FormatError, match="expected 14 digits, got 13"):
        check_gtin("(01)0950600013435", "dm")
    # the Data Matrix GS1 path refuses a wrong GTIN, rendered or typed
    with pytest.raises(FormatError, match="wrong check digit"):
        load_pattern(render_spec('datamatrix:"(01){gtin}(21){serial}"',
                                 Variables(1, {"gtin": "09506000134353"}, NOW)))
    assert load_pattern('datamatrix:"(01)09506000134352(21)42"').code.text.startswith("(01)")


# ---------------------------------------------------------------------------- the counter
def _take(path) -> int:
    with locked(path) as c:
        n = c.next
        c.issue(n, job=f"job{n}.json")
        return n


def test_counter_is_created_issued_and_set(tmp_path):
    path = tmp_path / "serial.counter.json"
    with pytest.raises(FormatError, match="no such serial counter .a first serial creates"):
        _take(path)
    with locked(path) as c:
        c.create(7)
    assert [_take(path) for _ in range(3)] == [7, 8, 9]
    c = read_counter(path)
    assert c.next == 10 and [i.serial for i in c.issued] == [7, 8, 9]
    assert c.issued[-1].job == "job9.json" and lock_path(path).exists()
    with locked(path) as c, pytest.raises(FormatError, match="a serial counter exists .next 10"):
        c.create(1)
    with locked(path) as c:
        with pytest.raises(FormatError, match="serial 9 was issued already; next 9 would"):
            c.set_next(9)
        with pytest.raises(FormatError, match="serial 11 is not the next one .10."):
            c.issue(11)
        c.set_next(100)
    assert _take(path) == 100
    with locked(path) as c:
        c.set_next(5, force=True)
    assert read_counter(path).next == 5
    for _ in range(KEEP + 5):
        _take(path)
    assert len(read_counter(path).issued) == KEEP


@pytest.mark.parametrize("data, message", [
    ({"format": "insitu-serial-counter/1", "next": -1}, "next: expected a number >= 0, got -1"),
    ({"format": "insitu-serial-counter/1", "next": 1.5}, "next: expected an integer, got 1.5"),
    ({"format": "insitu-serial-counter/1"}, "next: missing (required)"),
    ({"format": "other/1", "next": 1}, "format: expected 'insitu-serial-counter/1'"),
    ([1], "expected a JSON object (a serial counter), got list"),
])
def test_a_bad_counter_file_is_one_line(tmp_path, data, message):
    path = tmp_path / "c.json"
    path.write_text(json.dumps(data))
    with pytest.raises(FormatError) as e:
        _take(path)
    assert str(e.value).startswith(f"{path}: ") and message in str(e.value), str(e.value)


def test_a_held_counter_times_out_with_one_line(tmp_path):
    path = tmp_path / "c.json"
    with locked(path) as c:
        c.create(1)
        with pytest.raises(FormatError, match="held by another process for 0.1 s"):
            with locked(path, timeout_s=0.1):
                pass


def test_threads_racing_never_take_the_same_serial(tmp_path):
    path = tmp_path / "c.json"
    with locked(path) as c:
        c.create(1)
    got, lock = [], threading.Lock()

    def worker():
        for _ in range(15):
            n = _take(path)
            with lock:
                got.append(n)

    threads = [threading.Thread(target=worker) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(got) == list(range(1, 91)) and read_counter(path).next == 91


def _process_takes(path, count, queue):
    queue.put([_take(path) for _ in range(count)])


def test_processes_racing_never_take_the_same_serial(tmp_path):
    path = tmp_path / "c.json"
    with locked(path) as c:
        c.create(1000)
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    procs = [ctx.Process(target=_process_takes, args=(path, 20, queue)) for _ in range(3)]
    for p in procs:
        p.start()
    got = sorted(n for _ in procs for n in queue.get(timeout=120))
    for p in procs:
        p.join(30)
        assert p.exitcode == 0
    assert got == list(range(1000, 1060)) and read_counter(path).next == 1060
