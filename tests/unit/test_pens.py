"""Pens: the pen table and its checks, the job's per-path pen settings (passes, delays,
wobble), the driver, the journal's passes semantics, the boards and the simulated burns."""

import hashlib
import json

import numpy as np
import pytest

from insitu.devices.galvo import Command, RecordingController, list_digest
from insitu.devices.lmc import L_MARK, L_ON_DELAY, LmcListBuilder, LmcSettings
from insitu.errors import DeviceError, FormatError
from insitu.formats.pens import DEFAULT_PENS, Delays, Pen, PenTable, Wobble, read_pens, write_pens
from insitu.geometry.beams import TwoMirrorHead
from insitu.marking import (
    GalvoDriver,
    LaserOverride,
    estimate_time,
    make_job,
    progress_path_for,
    read_job,
    run_job,
    with_pen,
    write_job,
)
from insitu.marking.run import resume_list

HEAD = TwoMirrorHead(350.0, 12.0)
PATH = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 5.0, 0.0], [0.0, 5.0, 0.0]])
DEEP = DEFAULT_PENS.pen("deep")


# --------------------------------------------------------------------------- the table
def test_pens_file_round_trip_and_default(tmp_path):
    f = tmp_path / "pens.json"
    write_pens(f, DEFAULT_PENS)
    assert read_pens(f) == DEFAULT_PENS
    assert DEFAULT_PENS.pen(None).name == "mark" and DEFAULT_PENS.pen("deep").passes == 2
    with pytest.raises(FormatError, match=r"pen: no pen 'laser'; the pens are 'mark', 'fine', "
                                          r"'deep' or 'bold'"):
        DEFAULT_PENS.pen("laser")


@pytest.mark.parametrize("change, message", [
    ({"power_pct": 120}, r"pens\[1\] \('deep'\)\.power_pct: 120 is outside 0 … 100 %"),
    ({"passes": 0}, r"pens\[1\] \('deep'\)\.passes: 0 is outside 1 … 100"),
    ({"delays_us": {"jump": -5}}, r"pens\[1\] \('deep'\)\.delays_us\.jump: -5 is outside"),
    ({"wobble": {"amplitude_mm": 0.1}}, r"\('deep'\)\.wobble: expected exactly one of"),
    ({"wobble": {"amplitude_mm": 9, "frequency_hz": 100}}, r"wobble\.amplitude_mm: 9 is outside"),
    ({"colour": "red"}, r"\('deep'\)\.colour: expected a colour #rrggbb, got 'red'"),
    ({"name": "mark"}, r"pens\[1\]\.name: pen 'mark' is defined twice"),
])
def test_every_pen_field_is_checked_in_one_line_naming_pen_and_field(tmp_path, change, message):
    pens = [{"name": "mark"}, {"name": "deep", **change}]
    f = tmp_path / "pens.json"
    f.write_text(json.dumps({"format": "insitu-pens/1", "default": "mark", "pens": pens}))
    with pytest.raises(FormatError, match=message) as e:
        read_pens(f)
    assert str(e.value).startswith(str(f)) and "\n" not in str(e.value)


def test_default_pen_must_be_one_of_the_pens(tmp_path):
    f = tmp_path / "pens.json"
    f.write_text(json.dumps({"format": "insitu-pens/1", "default": "x",
                             "pens": [{"name": "mark"}]}))
    with pytest.raises(FormatError, match="default: expected one of the pens, 'mark', got 'x'"):
        read_pens(f)


# --------------------------------------------------------------------------- the job
def test_pen_settings_travel_in_each_paths_laser(tmp_path):
    job = with_pen(make_job([PATH, PATH + [0, 10, 0]]), DEEP)
    f = tmp_path / "job.json"
    write_job(f, job)
    row = json.loads(f.read_text().splitlines()[-3].rstrip(","))
    assert row["laser"]["pen"] == "deep" and row["laser"]["passes"] == 2
    assert row["laser"]["delays_us"] == {"laser_on": 100.0, "laser_off": 150.0, "jump": 250.0,
                                         "mark": 150.0, "polygon": 100.0}
    back = read_job(f)
    assert back.digest() == job.digest() and back.path_passes(1) == 2
    assert back.path_laser(0).power_pct == 80.0 and back.pens() == {"deep": [0, 1]}


def test_an_older_jobs_digest_is_unchanged():
    """The journal of a job written before pens still matches it (same sha256)."""
    job = make_job([PATH], overrides={0: LaserOverride(power_pct=50.0)})
    h = hashlib.sha256()
    h.update(job.laser.model_dump_json().encode())
    h.update(b"")
    h.update(np.ascontiguousarray(job.paths[0].points).tobytes())
    h.update(b'{"power_pct":50.0,"frequency_khz":null,"mark_speed_mm_s":null,'
             b'"jump_speed_mm_s":null}')
    assert job.digest() == h.hexdigest()


def test_time_estimate_counts_passes_jump_speed_and_delays():
    one = estimate_time(make_job([PATH]))
    pen = Pen(name="p", passes=3, jump_speed_mm_s=1000.0,
              delays_us=Delays(laser_on=1000, laser_off=1000, jump=1000, mark=1000, polygon=0))
    three = estimate_time(with_pen(make_job([PATH]), pen))
    assert three.mark_s == pytest.approx(3 * one.mark_s)
    assert three.mark_mm == pytest.approx(3 * one.mark_mm)
    assert three.jump_mm == pytest.approx(2 * 5.0)             # back to the start twice
    assert three.jump_s == pytest.approx(10.0 / 1000.0)
    assert three.delay_s == pytest.approx(3 * 4000e-6)


# --------------------------------------------------------------------------- the driver
def test_driver_marks_each_pass_with_the_pens_delays_and_wobble():
    pen = Pen(name="p", passes=2, delays_us=Delays(jump=300.0, laser_on=70.0),
              wobble=Wobble(amplitude_mm=0.2, pitch_mm=0.5))
    cmds = GalvoDriver(HEAD).compile(with_pen(make_job([PATH]), pen))[0]
    ops = [c.op for c in cmds]
    assert ops.count("mark_abs_3d") == 2 * 3 and ops.count("laser_on") == 2
    assert ops.count("jump_abs_3d") == 2
    assert [c.args[0] for c in cmds if c.op == "jump_delay"] == [300.0, 300.0]
    assert [c.args[0] for c in cmds if c.op == "laser_on_delay"] == [70.0, 70.0]
    wob = [c for c in cmds if c.op == "set_wobble"]
    assert len(wob) == 1 and wob[0].args == pytest.approx((0.2, 500.0 / 0.5))
    assert ops.index("set_wobble") < ops.index("laser_on")
    plain = GalvoDriver(HEAD).compile(make_job([PATH]))[0]
    assert "set_wobble" not in [c.op for c in plain] and len(plain) < len(cmds)


def test_continue_resumes_within_the_pass_and_marks_the_passes_after_it():
    cmds = GalvoDriver(HEAD).compile(with_pen(make_job([PATH]), DEEP))[0]
    marks = [c for c in cmds if c.op == "mark_abs_3d"]
    rest = resume_list(cmds, 4)                  # pass 1 done, 1 mark of pass 2
    got = [c for c in rest if c.op == "mark_abs_3d"]
    assert got == marks[4:]
    jumps = [c for c in rest if c.op == "jump_abs_3d"]
    assert jumps == [Command("jump_abs_3d", marks[3].args)]      # where mark 4 ended
    assert [c.op for c in rest].count("laser_on") == 1
    assert "set_power" in [c.op for c in rest]                    # the pen's settings stay
    assert resume_list(cmds, 6) == []


class CutController(RecordingController):
    """Stops (DeviceError) after ``cut`` marks of its first list; reports its position."""

    def __init__(self, cut):
        super().__init__()
        self.cut, self._pos = cut, None

    def execute(self, commands):
        from insitu.devices.galvo import ListPosition
        marks = 0
        for i, c in enumerate(commands):
            if c.op == "mark_abs_3d" and self.cut is not None and marks == self.cut:
                self._pos, self.cut = ListPosition(list_digest(commands), i), None
                raise DeviceError("injected fault")
            marks += c.op == "mark_abs_3d"
            super().execute([c])
        self._pos = ListPosition(list_digest(commands), len(commands))

    def position(self):
        return self._pos


@pytest.mark.parametrize("choice, marked_again", [("remark", 6), ("continue", 2)])
def test_a_cut_path_with_passes_is_marked_again_whole_or_continued(tmp_path, choice,
                                                                  marked_again):
    """remark repeats all the path's passes; continue marks what the board did not."""
    job = with_pen(make_job([PATH]), DEEP)
    f = tmp_path / "job.json"
    write_job(f, job)
    cc = CutController(cut=4)
    with pytest.raises(DeviceError):
        run_job(job, GalvoDriver(HEAD), cc, progress_path_for(f))
    before = len([c for c in cc.commands if c.op == "mark_abs_3d"])
    assert before == 4
    r = run_job(job, GalvoDriver(HEAD), cc, progress_path_for(f), resume=True, cut_path=choice)
    assert r.state == "done"
    assert len([c for c in cc.commands if c.op == "mark_abs_3d"]) - before == marked_again


# --------------------------------------------------------------------------- the boards
def test_lmc_traces_the_wobble_in_the_list():
    b = LmcListBuilder(HEAD, LmcSettings(bits_per_deg=1500.0))
    pen = Pen(name="p", mark_speed_mm_s=100.0, wobble=Wobble(amplitude_mm=0.5, frequency_hz=100),
              delays_us=Delays(laser_on=70.0))
    cmds = GalvoDriver(HEAD).compile(with_pen(make_job([PATH[:2]]), pen))[0]
    entries, marking = b.commands(cmds)
    assert (L_ON_DELAY, 70, 0, 0, 0, 0) in entries                # the pen's delay, its list
    marks = np.array([e[1:3] for e in entries if e[0] == L_MARK], float)
    # 10 mm at 100 mm/s = 0.1 s = 10 turns, 16 per turn
    assert marking and len(marks) == 160
    centre_y = marks[:, 1].mean()
    r_units = np.abs(marks[:, 1] - centre_y).max()
    assert r_units == pytest.approx(0.5 * b.units_per_mm, rel=0.02)
    plain, _ = b.commands(GalvoDriver(HEAD).compile(make_job([PATH[:2]]))[0])
    assert sum(e[0] == L_MARK for e in plain) == 1        # a list without it: no wobble


def test_lmc_wobble_needs_a_mark_speed():
    from insitu.errors import SafetyError
    b = LmcListBuilder(HEAD, LmcSettings(bits_per_deg=1500.0))
    with pytest.raises(SafetyError, match="wobble needs the mark speed"):
        b.commands([Command("set_wobble", (0.1, 100.0)), Command("laser_on"),
                    Command("mark_abs_3d", (1.0, 0.0, 0.0))])
    slow = [Command("set_mark_speed", (0.1,)), Command("set_wobble", (0.1, 50000.0)),
            Command("laser_on"), Command("mark_abs_3d", (1.0, 0.0, 0.0))]
    with pytest.raises(SafetyError, match=r"needs [\d,]+ list points \(at most 1,000,000"):
        b.commands(slow)


def test_pen_table_replaced_keeps_the_default():
    t = DEFAULT_PENS.replaced(DEEP.model_copy(update={"name": "deeper"}), "deep")
    assert t.names == ("mark", "fine", "deeper", "bold") and t.default == "mark"
    assert PenTable(default="a", pens=(Pen(name="a"),)).replaced(Pen(name="b")).names == ("a", "b")


def test_time_left_weighs_the_paths_still_to_mark_by_their_passes():
    from insitu.marking import LaserOverride, path_seconds
    from insitu.ui.model.time_left import TimeLeft
    job = make_job([PATH, PATH, PATH], overrides={2: LaserOverride.of_pen(
        Pen(name="p", passes=3))})
    sec = path_seconds(job)
    assert sec.sum() == pytest.approx(estimate_time(job).total_s)
    assert sec[2] > 2.5 * sec[1]
    # the first path took twice its estimate: the rest will too
    assert TimeLeft(sec).update(0, 0.0) == pytest.approx(sec.sum())
    assert TimeLeft(sec, start_done=2).update(2, 0.0) == pytest.approx(sec[2])  # resumed


def test_board_checks_cover_delays_and_the_wobble(tmp_path):
    """Controller.check (every list built, nothing sent) refuses a negative or non-finite
    delay, a negative wobble, and on an RTC a wobble beyond the bit range."""
    from pathlib import Path

    from insitu.devices.galvo import check_setting
    from insitu.devices.rtc import RtcListBuilder, RtcSettings
    from insitu.errors import SafetyError
    with pytest.raises(SafetyError, match=r"RTC: jump delay -1 µs: expected a finite number ≥ 0"):
        check_setting("RTC", Command("jump_delay", (-1.0,)))
    with pytest.raises(SafetyError, match=r"LMC: laser on delay nan µs"):
        check_setting("LMC", Command("laser_on_delay", (float("nan"),)))
    with pytest.raises(SafetyError, match=r"LMC: wobble -0.1 mm at 100 Hz: expected finite"):
        LmcListBuilder(HEAD, LmcSettings(bits_per_deg=1500.0)).commands(
            [Command("set_wobble", (-0.1, 100.0))])
    rtc = RtcListBuilder(HEAD, RtcSettings(library=Path("x.so"), correction_file=Path("x.ct5"),
                                           k_bits_per_mm=200000.0))
    with pytest.raises(SafetyError, match=r"RTC: wobble 5 mm is 1000000 bits, beyond"):
        rtc.calls([Command("set_wobble", (5.0, 100.0))])
