"""The station clock: what the simulated devices would take on a real station (camera frames
with the head's jumps, marking, the stage), kept apart from the computer's CPU, and reported
by a scan, a marking run and production."""

import json

import numpy as np
import pytest

from insitu.devices.clock import StationClock, StationTime, StepTimer
from insitu.errors import ConfigError, SafetyError
from insitu.marking import GalvoDriver, estimate_time, make_job, run_job
from insitu.services.scan import scan_live
from insitu.services.station import connect
from insitu.sim.clock import SimTiming
from insitu.sim.controller import SimController
from insitu.sim.devices import SimCamera, SimScanHead, SimStage
from insitu.sim.world import sim_world


def test_clock_adds_by_kind_and_refuses_nonsense():
    clock = StationClock()
    t0 = clock.now()
    clock.advance("frames", 0.5)
    clock.advance("marking", 1.25)
    span = clock.now() - t0
    assert span.seconds == pytest.approx(1.75) and span.by["frames"] == 0.5
    assert (span + span).seconds == pytest.approx(3.5)
    with pytest.raises(ValueError, match="kind 'coffee'"):
        clock.advance("coffee", 1.0)
    with pytest.raises(ValueError, match="expected ≥ 0"):
        clock.advance("frames", -1.0)
    assert StationTime().seconds == 0.0


def test_a_frame_takes_its_exposure_or_its_readout_whichever_is_longer():
    world = sim_world("step-block", binning=8)
    cam, head, t = SimCamera(world), SimScanHead(world), world.timing
    full = t.readout_s(cam.height, cam.width)
    cam.set_exposure(40.0)                              # the laser off: the camera's own
    before = world.clock.now()
    cam.grab()
    assert (world.clock.now() - before).seconds == pytest.approx(t.trigger_us * 1e-6 + 0.040)
    head.show_line([0.0, -40.0], [0.0, 40.0])           # a line: one sweep of its 80 mm
    before = world.clock.now()
    cam.grab()
    jump = t.jump_s(40.0)                                # from the field centre to (0, −40)
    sweep = 80.0 / t.max_sweep_mm_s()
    assert t.light_s(80.0, 4.0) < sweep                 # its light takes less than the sweep
    assert (world.clock.now() - before).seconds == pytest.approx(
        max(jump + t.trigger_us * 1e-6 + sweep, full))
    cam.set_exposure(0.1)
    cam.set_region_of_interest((0, 0, cam.width, 32))   # fewer rows: faster
    head.off()
    before = world.clock.now()
    image = cam.grab()
    assert (world.clock.now() - before).seconds == pytest.approx(t.readout_s(32, cam.width))
    assert not image[32:].any()                         # nothing read outside it


def test_the_scans_light_is_power_times_dwell_at_a_power_that_never_marks():
    """The scan's power: its pulses' peak fluence 2E / (πw²) a quarter of the lowest
    ablation threshold of the station's materials (the rig file's constants are those of the
    built-in material table's source); a frame of lines is exposed for the light they need
    at that power (twice the exposure: twice the light) or one pass over them."""
    from dataclasses import replace

    from insitu.formats.materials import DEFAULT_MATERIALS
    t = SimTiming()
    table = DEFAULT_MATERIALS
    assert t.scan_threshold_j_cm2 == min(m.threshold_j_cm2 for m in table.materials)
    assert (t.scan_spot_um, t.source_power_w) == (table.laser.spot_um, table.laser.power_w)
    pulse_j = t.scan_power_w() / (t.scan_pulse_khz * 1e3)
    fluence = 2 * pulse_j / (np.pi * (t.scan_spot_um / 2 * 1e-4) ** 2)
    assert fluence == pytest.approx(t.scan_fluence_share * t.scan_threshold_j_cm2)
    assert t.max_sweep_mm_s() == t.line_speed_mm_s      # 1 MHz: pulses 10 µm apart
    q_switched = replace(t, scan_pulse_khz=40.0)        # 40 kHz: one pulse a spot at 2 m/s
    assert q_switched.max_sweep_mm_s() == pytest.approx(2000.0)
    assert q_switched.scan_power_w() == pytest.approx(t.scan_power_w() * 0.04)

    world = sim_world("step-block", binning=8)
    world.timing = replace(t, scan_threshold_j_cm2=2e-5)  # a dim scan: its light bounds
    cam, head = SimCamera(world), SimScanHead(world)
    lines = [([0.0, -40.0], [0.0, 40.0]), ([8.0, -40.0], [8.0, 40.0])]
    spent = []
    for exposure, drawn in ((10.0, lines[:1]), (20.0, lines[:1]), (20.0, lines)):
        cam.set_exposure(exposure)
        head.show_lines(drawn)
        cam.grab()                                      # the jump to the list counted here
        before = world.clock.now()
        cam.grab()
        spent.append((world.clock.now() - before).seconds - t.trigger_us * 1e-6)
    light, t = world.timing.light_s(80.0), world.timing
    sweep = 80.0 / t.max_sweep_mm_s()
    assert light > 20 * sweep
    passes = np.ceil(light / sweep)                     # whole passes, back and forth
    assert spent[:2] == pytest.approx([passes * sweep, np.ceil(2 * light / sweep) * sweep])
    # two lines: whole cycles (two sweeps, the jumps across and back), less the last jump
    across, back = t.jump_s(np.hypot(8.0, 80.0)), t.jump_s(np.hypot(8.0, 80.0))
    assert spent[2] == pytest.approx(passes * (2 * sweep + across + back) - back)
    with pytest.raises(SafetyError, match="at most the head's 10000 mm/s"):
        head.set_line_speed(12000.0)


def test_lines_in_one_exposure_take_one_pass_over_all_of_them():
    from dataclasses import replace

    t = SimTiming(line_speed_mm_s=1000.0, jump_mm_s=2000.0, settle_ms=0.5)
    lines = [(np.array([0.0, -40.0]), np.array([0.0, 40.0])),
             (np.array([8.0, -40.0]), np.array([8.0, 40.0]))]
    # 2 × 80 mm swept, jumps of √(8² + 80²) mm (end of one to start of the next)
    jump = np.hypot(8.0, 80.0) / 2000.0 + 0.5e-3
    # the light of 2 lines takes far less than a pass: one pass, no jump back to the first
    assert t.exposure_s(lines, 20.0, None) == pytest.approx(0.160 + jump)
    dim = replace(t, scan_threshold_j_cm2=1e-5)          # light for ~3 passes: whole cycles
    passes = np.ceil(dim.light_s(160.0) / 0.160)
    assert passes > 1 and dim.exposure_s(lines, 20.0, None) == pytest.approx(
        passes * (0.160 + 2 * jump) - jump)
    assert t.exposure_s(lines[:1], 10.0, 500.0) == pytest.approx(0.160)
    assert t.frame_s(10.0, 0.002, 0.001) == pytest.approx(0.012 + t.trigger_us * 1e-6)


def test_marking_and_stage_advance_the_clock_by_their_own_models():
    world = sim_world("step-block", binning=8)
    ctrl, stage = SimController(world), SimStage(world)
    job = make_job([np.array([[0.0, 0.0, 15.0], [5.0, 0.0, 15.0], [5.0, 5.0, 15.0]])])
    before = world.clock.now()
    run_job(job, GalvoDriver.from_config(world.rig.operator.head), ctrl, None)
    spent = world.clock.now() - before
    assert spent.by["marking"] == pytest.approx(ctrl.elapsed_s)
    assert spent.by["marking"] == pytest.approx(estimate_time(job).total_s, rel=0.05)
    assert spent.simulation_cpu_s > 0                   # burning it is the simulator's work
    stage.move_z(10.0)
    assert (world.clock.now() - before).by["stage"] == pytest.approx(
        world.timing.stage_s(10.0))


def test_a_scan_reports_station_seconds_beside_its_cpu():
    with connect(None, "step-block", 0, 4) as station:
        timer = StepTimer(station.clock)
        result = scan_live(station, 1.0, (-5.0, 5.0, -40.0, 40.0))
        spent = timer.elapsed()
    s = result.summary
    assert s.station_s == pytest.approx(spent.station, rel=1e-6)
    # 11 line frames, each at least one sweep of its line, and the room light's frames
    assert s.station_s > 11 * 80.0 / station.world.timing.max_sweep_mm_s()
    assert 0 < s.cpu_s < s.seconds                      # the simulator's drawing left out


def test_produce_logs_station_and_cpu_seconds_per_step(tmp_path):
    from insitu.cli.produce import part_line
    from insitu.formats.pointcloud import write_ply
    from insitu.formats.production_log import read_log
    from insitu.formats.recipe import Recipe, RecipeScan
    from insitu.marking import Placement
    from insitu.services import production
    from insitu.services.locate import Located
    from insitu.services.part_reading import read_part

    with connect(None, "step-block", 0, 4) as station:
        write_ply(tmp_path / "ref.ply", scan_live(station, 1.0).cloud)
        recipe = Recipe(tmp_path / "ref.ply", "cloud", (
            Placement('text:"A";size=2', (0.0, -30.0), 4.0, 10.0),), scan=RecipeScan(
                margin_mm=4.0, spacing_mm=1.0), workpiece="step-block")
        where = lambda cloud, room_light=None: Located(np.eye(4), 1.0, 0.0)  # noqa: E731
        run = production.Production(recipe, station, tmp_path / "run.jsonl", 1, where,
                                    read_part)
        production.produce(run)
    rec = read_log(tmp_path / "run.jsonl")[0]
    assert rec.outcome == "marked"
    assert rec.scan_station_s > 0.1 and rec.mark_station_s > 0 and rec.read_station_s > 0
    assert rec.locate_station_s == 0 and rec.plan_cpu_s > 0
    assert "station" in part_line(rec).plain
    line = json.loads((tmp_path / "run.jsonl").read_text().splitlines()[0])
    assert "scan_station_s" in line and "scan_cpu_s" in line
    header = (tmp_path / "run.csv").read_text().splitlines()[0].split(",")
    assert "mark_station_s" in header


def test_mark_run_prints_station_seconds(tmp_path, capsys):
    from insitu.cli.job import run_on_station
    from insitu.marking import write_job

    job = make_job([np.array([[0.0, -30.0, 3.0], [4.0, -30.0, 3.0]])])
    write_job(tmp_path / "job.json", job)
    with connect(None, "step-block", 0, 8) as station:
        run_on_station(station, job, tmp_path / "job.json", False, False, None)
    out = capsys.readouterr().out
    assert "marking: station 0." in out and "CPU" in out


def test_the_rig_file_states_the_simulated_stations_timing(tmp_path):
    """``options.sim_timing`` sets the simulated devices' timing (a slower sensor row: a
    longer readout); an unknown key or a value ≤ 0 is refused naming it."""
    rig = {"kind": "rig", "camera": "sim", "scan_head": "sim", "stage": "sim",
           "options": {"sim_timing": {"row_us": 30.0, "blank_rows": 4}}}
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(rig))
    with connect(path, "step-block", binning=8) as station:
        t = station.world.timing
        assert (t.row_us, t.blank_rows, t.link_gbit_s) == (30.0, 4, SimTiming().link_gbit_s)
        assert t.readout_s(100, 16) == pytest.approx(104 * 30e-6)
    for bad, said in (({"row_ms": 1.0}, "options.sim_timing.row_ms: unknown"),
                      ({"trigger_us": 0}, "options.sim_timing.trigger_us: 0: expected a number"),
                      ({"blank_rows": 2.5}, "options.sim_timing.blank_rows: 2.5"),
                      ({"scan_fluence_share": 1.0}, "scan_fluence_share: 1.0: expected < 1")):
        path.write_text(json.dumps({**rig, "options": {"sim_timing": bad}}))
        with pytest.raises(ConfigError, match=said):
            connect(path, "step-block", binning=8)
