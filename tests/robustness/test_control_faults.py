"""The control loop's safety model against boards that misbehave the way real boards do.

Each board is the simulated grasp board (bendsense.sim.gripper.GraspBoard) on a real
pseudo-terminal, wrapped to fail from frame 300 on (0.3 s at 1 kHz): it stops reporting a
pressure line, loses its pressure sensor, reads 900 kPa, or dies (the pseudo-terminal
closed). The wrapper keeps every SETPOINT the board received: that log, not what the loop
says, is the truth each test checks the loop's words against.
"""

import copy
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import board_caught_up

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.control import ControlStop, Grasp, PIController, Safety, force_limit_n, run, zero_report
from bendsense.device.driver import Driver
from bendsense.device.simdevice import Faults, SimulatedDevice
from bendsense.errors import ArgumentError
from bendsense.pipeline import LiveProcessor
from bendsense.pipeline.gripper import GripperProcessor
from bendsense.sim import gripper_config
from bendsense.sim.grasp import GraspObject
from bendsense.sim.gripper import GraspBoard

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals"),
              pytest.mark.realtime]
CONFIG = bendsense.load_config()
GRIPPER = gripper_config(3)
S_C, RATE, LIMIT_PA, FAULT_AT = 0.10, 1000.0, 100e3, 300
GRIPPER_CHANNELS = 48
STEP_PA = 2000.0  # the boards' pressure tables: coarse, to build them fast (the faults need no precise forces)


class Faulty:
    """The board, keeping every SETPOINT it receives; from frame ``at`` on it reports ``fault(pressure)``."""

    def __init__(self, board, at=None, fault=None):
        self.board, self.at, self.fault = board, at, fault
        self.received = []  # (line, pressure_pa), in the order they arrived
        self.frames = 0

    def setpoint(self, line, pressure_pa):
        self.received.append((line, pressure_pa))
        return self.board.setpoint(line, pressure_pa)

    def __call__(self, k):
        p, counts, truth = self.board(k)
        self.frames = k + 1
        if self.at is not None and k >= self.at:
            p = self.fault(p)
        return p, counts, truth

    def last(self) -> dict:
        """The last set-point each line received."""
        return dict(self.received)


class Truth:
    """The simulator's truth of every frame (what ``sim-device --truth`` writes)."""

    def __init__(self):
        self.rows, self.seq, self.t_us = [], [], []  # by frame index

    def write(self, seq, t_us, truth):
        self.rows.append(truth)
        self.seq.append(seq)
        self.t_us.append(t_us)

    def flush(self):
        pass

    def column(self, name):
        return np.array([r[name] for r in self.rows])


@pytest.fixture(scope="module")
def single_board():
    return GraspBoard(CONFIG, [GraspObject(S_C, 40e3)], rate_hz=RATE, seed=0, step_pa=STEP_PA)


@pytest.fixture(scope="module")
def gripper_board():
    return GraspBoard(GRIPPER, [GraspObject(S_C, p) for p in (40e3, 45e3, 35e3)], rate_hz=RATE, seed=0,
                      step_pa=STEP_PA)


@pytest.fixture(scope="module")
def gripper_processor(calibration_path):
    proc = GripperProcessor(Calibration.load(calibration_path), GRIPPER, load="contact", contact_s_m=S_C,
                            constraint="normal", bandwidth_hz=30.0)
    proc.warm_up()
    return proc


@pytest.fixture(scope="module")
def files(calibration_path, tmp_path_factory):
    """The gripper's config on disk (the single actuator's is the shipped one) and the calibration."""
    root = tmp_path_factory.mktemp("faults")
    bendsense.config.save_config(GRIPPER, root / "gripper.yaml")
    return {"calibration": str(calibration_path), "gripper": str(root / "gripper.yaml")}


def pis(fingers):
    return Grasp([PIController(0.15, line=f.pressure_line, finger=f.name, max_pressure_pa=LIMIT_PA)
                  for f in GRIPPER.fingers if f.name in fingers])


def gripper_run(board, processor, controller, truth=None, **kw):
    """The loop on the gripper board; returns (the result or the ControlStop, seconds the loop ran)."""
    processor.reset()
    with SimulatedDevice(board, rate_hz=RATE, n_channels=GRIPPER_CHANNELS, truth=truth) as dev, \
            Driver(dev.port) as driver:
        driver.start()
        t0 = time.monotonic()
        try:
            out = run(driver, processor, controller, max_pressure_pa=LIMIT_PA, seconds=2.0,
                      safety=Safety(silence_s=1.0), **kw)
        except ControlStop as err:
            out = err
        ran = time.monotonic() - t0
        board_caught_up(dev, driver)  # the zeros reach the board
    return out, ran


def control_cli(port, files, *extra):
    args = ["control", port, "--calibration", files["calibration"], "--target-force-n", "0.15", "--load", "contact",
            "--contact-s-m", str(S_C), *extra]
    return CliRunner().invoke(main, args)


def one_error_line(res) -> str:
    errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "Traceback" not in res.output, res.output
    return errors[0]


def test_a_line_the_board_stops_reporting_is_let_go_and_said_to_be_unconfirmed(gripper_board, gripper_processor):
    # from frame 300 the board's SAMPLEs carry lines 0 and 1 only; line 2 (the middle finger's) is pressurised
    board = Faulty(copy.deepcopy(gripper_board), FAULT_AT, lambda p: p[:2])
    err, ran = gripper_run(board, gripper_processor, pis(("thumb", "index", "middle")))
    assert isinstance(err, ControlStop), err
    # the middle finger has no pressure, so no force: it stops like a model flag, within 10 ms of board time
    assert re.search(r"finger middle: no force \(no_pressure\) for 10 ms .* at t = 0\.3[01]\d s", err.reason)
    assert err.result.frames <= FAULT_AT + 30 and ran < 1.5
    pressurised = [v for line, v in board.received if line == 2]
    assert max(pressurised) > 10e3  # line 2 was driven before the fault ...
    assert board.last() == {0: 0.0, 1: 0.0, 2: 0.0}  # ... and every line's last set-point is 0, line 2's too
    assert board.board.regulators.setpoint_pa[2] == 0.0
    zeros = {z.line: z for z in err.result.zeros}
    assert all(z.sent for z in zeros.values()) and err.result.unsent == ()
    assert [k for k, z in zeros.items() if not z.reported] == [2]
    assert zero_report(err.result) == ("set-point 0 sent on every pressure line (0, 1, 2); line 2 not confirmed "
                                       "(the board does not report its pressure)")


@pytest.mark.parametrize(("reading_pa", "why"), [
    (900e3, "900 kPa at seq {seq}, beyond the pressure limit 100 kPa (+5 kPa for regulator ripple)"),
    (-50e3, "-50 kPa at seq {seq}, below 0 (-5 kPa tolerance)")], ids=["900kPa", "negative"])
def test_a_pressure_outside_the_limits_on_an_uncontrolled_line_stops_the_loop(gripper_board, gripper_processor,
                                                                               reading_pa, why):
    # the thumb is controlled; from frame 300 the board reads nonsense on line 2 (a failed sensor or a stuck valve)
    board = Faulty(copy.deepcopy(gripper_board), FAULT_AT, lambda p: (p[0], p[1], reading_pa))
    truth = Truth()
    err, ran = gripper_run(board, gripper_processor, pis(("thumb",)), n_lines=3, truth=truth)
    assert isinstance(err, ControlStop), err
    assert err.reason.startswith("line 2 reads " + why.format(seq=truth.seq[FAULT_AT])), err.reason
    assert err.result.frames <= FAULT_AT and ran < 1.5  # the frame is checked before it is processed
    assert board.last() == {0: 0.0, 1: 0.0, 2: 0.0}
    assert err.result.held == (1, 2)
    assert {line for line, v in board.received if v > 0} == {0}  # only the thumb's line was ever driven


def test_a_failed_pressure_sensor_stops_the_command(single_board, files):
    # from frame 300 the board reports no pressure (0x7FFFFFFF) on its one line: the finger has no force
    board = Faulty(copy.deepcopy(single_board), FAULT_AT, lambda p: None)
    with SimulatedDevice(board, rate_hz=RATE) as dev:
        res = control_cli(dev.port, files, "--seconds", "2", "--silence-s", "1")
        board_caught_up(dev)  # the zeros reach the board
    assert res.exit_code == 1, res.output
    line = one_error_line(res)
    assert re.match(r"Error: control stopped: no force \(no_pressure\) for 10 ms \(limit 10 ms\) at t = 0\.3[01]\d s",
                    line), line
    # sent, and said to be unconfirmed: the board reports no pressure on its line any more
    assert line.endswith("; set-point 0 sent on every pressure line (0); line 0 not confirmed (the board does not "
                         "report its pressure)")
    assert max(v for _, v in board.received) > 10e3 and board.received[-1] == (0, 0.0)
    assert board.frames < FAULT_AT + 200  # stopped at once, not at --seconds


def test_a_board_reading_900_kpa_stops_the_command(single_board, files):
    board = Faulty(copy.deepcopy(single_board), FAULT_AT, lambda p: 900e3)
    truth = Truth()
    with SimulatedDevice(board, rate_hz=RATE, truth=truth) as dev:
        res = control_cli(dev.port, files, "--seconds", "2", "--silence-s", "1", "--max-pressure-kpa", "60")
        board_caught_up(dev)  # the zeros reach the board
    assert res.exit_code == 1, res.output
    line = one_error_line(res)
    assert line.startswith(f"Error: control stopped: line 0 reads 900 kPa at seq {truth.seq[FAULT_AT]}, "
                           "beyond the pressure limit 60 kPa (+5 kPa for regulator ripple)"), line
    # its regulator let go (the board's own record), but its sensor still reads 900 kPa: said, not called confirmed
    assert re.search(r"; set-point 0 sent on every pressure line \(0\); line 0 did not fall: 900 kPa after 0\.5\d* s$",
                     line), line
    assert max(v for _, v in board.received) <= 60e3 and board.received[-1] == (0, 0.0)
    assert board.board.regulators.setpoint_pa[0] == 0.0
    setpoint = truth.column("setpoint_pa")  # the board's own set-point, frame by frame
    let_go = FAULT_AT + int(np.flatnonzero(setpoint[FAULT_AT:] == 0.0)[0])
    assert setpoint[FAULT_AT] > 0 and let_go < FAULT_AT + 200 and np.all(setpoint[let_go:] == 0.0)  # at once


def test_a_board_that_dies_is_said_to_keep_its_pressure(single_board, files, caplog):
    # the board closes its port after 300 frames, its line pressurised: no zero can reach it, and the loop says so
    board = Faulty(copy.deepcopy(single_board))
    with SimulatedDevice(board, rate_hz=RATE, faults=Faults(disconnect_after=FAULT_AT)) as dev:
        t0 = time.monotonic()
        res = control_cli(dev.port, files, "--seconds", "5")
        ran = time.monotonic() - t0
    assert res.exit_code == 1, res.output
    line = one_error_line(res)
    assert line.startswith("Error: control stopped: no frame from the board for "), line
    assert "set-point 0 could NOT be sent on line 0 (" in line and "it may still be pressurised" in line
    assert "sent on every" not in res.output
    # in a person's words, each once: the read that failed, the heartbeat (not every 50 ms), the closed port
    said = res.output + caplog.text
    assert "read failed (Input/output error)" in said and said.count("heartbeat not sent") <= 1, said
    assert "the port is closed: its last read failed" in line and "not open" not in said and "Errno" not in said
    # the board's own log: its last set-point is the loop's last pressure, never a zero: what the loop said
    first = next(i for i, (_, v) in enumerate(board.received) if v > 0)  # the loop's first block sends 0 (no time)
    assert board.received[-1][1] > 10e3 and all(v > 0 for _, v in board.received[first:])
    assert ran < 4.0


def test_the_library_records_a_zero_it_could_not_send(single_board, calibration_path):
    proc = LiveProcessor(Calibration.load(calibration_path), CONFIG, load="contact", contact_s_m=S_C,
                         constraint="normal", bandwidth_hz=30.0)
    proc.warm_up()
    board = Faulty(copy.deepcopy(single_board))
    with SimulatedDevice(board, rate_hz=RATE, faults=Faults(disconnect_after=FAULT_AT)) as dev, \
            Driver(dev.port) as driver:
        driver.start()
        with pytest.raises(ControlStop, match="no frame from the board") as info:
            run(driver, proc, PIController(0.15, max_pressure_pa=LIMIT_PA), max_pressure_pa=LIMIT_PA, seconds=5.0)
    result = info.value.result
    assert result.unsent == (0,) and np.isnan(result.zero_latency_s)
    assert not result.zeros[0].sent and "write failed" in result.zeros[0].error
    assert "Errno" not in result.zeros[0].error  # a person's words: "Input/output error", not the errno
    assert board.received[-1][1] > 0


def test_a_gripper_config_on_a_board_without_its_channels_is_refused_before_the_board_is_driven(single_board, files):
    board = Faulty(copy.deepcopy(single_board))  # 16 channels; the gripper's fingers read up to channel 48
    with SimulatedDevice(board, rate_hz=RATE) as dev:
        res = CliRunner().invoke(main, ["control", dev.port, "--config", files["gripper"], "--calibration",
                                        files["calibration"], "--target-force-n", "0.15", "--seconds", "1"])
    assert res.exit_code == 1 and one_error_line(res).endswith(
        "(the board's HELLO): 16 channels, but finger index reads channel 32 (fingers[1].channels of the "
        "config)"), res.output
    assert "holding" not in res.output and board.received == [] and board.frames == 0  # never started, never driven


def test_a_calibration_of_another_sensor_is_named_by_its_file(tmp_path):
    from helpers import linear_calibration

    linear_calibration(offset=np.full(8, 2000.0), noise_std=None, sensor=None).save(tmp_path / "cal8.yaml")
    res = CliRunner().invoke(main, ["control", str(tmp_path / "no-such-port"), "--calibration",
                                    str(tmp_path / "cal8.yaml"), "--target-force-n", "0.15", "--seconds", "1"])
    assert res.exit_code == 1 and one_error_line(res).startswith(f"Error: {tmp_path / 'cal8.yaml'}: the calibration "
                                                                 "has 8 channels, but the config's sensor has 16"), \
        res.output


def test_an_actuator_config_on_a_gripper_board_is_refused_before_the_board_is_driven(gripper_board, files):
    board = Faulty(copy.deepcopy(gripper_board))  # the gripper's channels; the actuator's calibration reads 16
    with SimulatedDevice(board, rate_hz=RATE, n_channels=GRIPPER_CHANNELS) as dev:
        res = CliRunner().invoke(main, ["control", dev.port, "--calibration", files["calibration"],
                                        "--target-force-n", "0.15", "--seconds", "1"])
    assert res.exit_code == 1 and one_error_line(res).endswith(
        f"(the board's HELLO): {GRIPPER_CHANNELS} channels, but the calibration reads 16 (a gripper's board: give "
        "its config with fingers: as --config)"), res.output
    assert "holding" not in res.output and board.received == []  # never driven


def test_a_finger_subset_holds_the_other_lines_at_zero(gripper_board, files, tmp_path):
    # the board's own profile would close every finger (70 kPa); --finger thumb must hold the others at 0
    board = Faulty(copy.deepcopy(gripper_board))
    truth, out = Truth(), tmp_path / "s"
    with SimulatedDevice(board, rate_hz=RATE, n_channels=GRIPPER_CHANNELS, truth=truth) as dev:
        res = CliRunner().invoke(main, ["control", dev.port, "--config", files["gripper"], "--calibration",
                                        files["calibration"], "--target-force-n", "0.15", "--finger", "thumb",
                                        "--load", "contact", "--contact-s-m", str(S_C), "--max-pressure-kpa", "60",
                                        "--seconds", "1", "--silence-s", "1", "-o", str(out)])
        board_caught_up(dev)  # the zeros reach the board
    assert res.exit_code == 0, res.output
    assert "lines 1, 2 not controlled: held at set-point 0" in res.output
    assert "set-point 0 sent on every pressure line (0, 1, 2)" in res.output
    held = [(line, v) for line, v in board.received if line != 0]
    assert held[:2] == [(1, 0.0), (2, 0.0)] and all(v == 0.0 for _, v in held)  # from the first block, only zeros
    assert board.last() == {0: 0.0, 1: 0.0, 2: 0.0}
    assert max(v for line, v in board.received if line == 0) <= 60e3
    for k in (1, 2):  # the board's profile reached 35 kPa by 1 s; the held lines stayed at rest
        assert truth.column(f"line{k}_pressure_pa").max() < 1e3
    assert truth.column("line0_pressure_pa").max() <= 60e3
    # the recording reads back, the held lines at rest beside the driven one
    pressure = bendsense.read_session(out).pressure_pa
    assert pressure.shape[1] == 3 and pressure[:, 0].max() > 10e3 and pressure[:, 1:].max() < 1e3


def test_a_target_beyond_the_finger_is_refused_before_the_board_is_driven(single_board, files):
    board = Faulty(copy.deepcopy(single_board))
    with SimulatedDevice(board, rate_hz=RATE) as dev:
        res = CliRunner().invoke(main, ["control", dev.port, "--calibration", files["calibration"],
                                        "--target-force-n", "150"])  # 150 mN meant
    assert res.exit_code == 2, res.output
    bound = force_limit_n(CONFIG, LIMIT_PA)
    assert f"'--target-force-n': 150 N is beyond what the finger can press at the pressure limit 100 kPa (at most " \
           f"{bound:.3g} N" in " ".join(res.output.split())
    assert "Traceback" not in res.output and board.received == [] and dev.stats.commands == 0


def test_the_force_limit_is_beyond_what_the_simulated_board_presses(gripper_board):
    # the bound refuses only targets no grasp reaches: the simulated finger at the limit presses less
    fx, fy, _ = gripper_board.fingers["thumb"].lookup_one(LIMIT_PA)
    assert np.hypot(fx, fy) < force_limit_n(CONFIG, LIMIT_PA, S_C) / 1.5


def test_the_library_refuses_a_target_beyond_the_bound():
    bound = force_limit_n(CONFIG, LIMIT_PA, S_C)
    with pytest.raises(ArgumentError, match=r"target_force_n: 150 N is beyond what finger thumb can press"):
        PIController(150.0, finger="thumb", max_pressure_pa=LIMIT_PA, max_force_n=bound)
    grasp = Grasp([PIController(0.15, line=k, finger=n, max_pressure_pa=LIMIT_PA, max_force_n=b)
                   for k, (n, b) in enumerate((("thumb", 10.0), ("index", bound)))])
    with pytest.raises(ArgumentError, match="finger index can press"):
        grasp.target_force_n = 5.0
    assert [c.target_force_n for c in grasp.controllers] == [0.15, 0.15]  # nothing half-set


def test_a_pressure_limit_beyond_the_config_is_refused(files):
    res = CliRunner().invoke(main, ["control", "/dev/null", "--calibration", files["calibration"],
                                    "--target-force-n", "0.15", "--max-pressure-kpa", "300"])
    assert res.exit_code == 2, res.output
    assert ("'--max-pressure-kpa': 300 kPa is beyond the config's actuator.pressure_range_pa (up to 200 kPa)"
            in " ".join(res.output.split()))


@pytest.mark.parametrize("argv, message", [
    (["control", "--bandwidth-hz", "1e-9"], "'--bandwidth-hz': expected > 5, got 1e-09"),  # a frozen track: overpress
    (["control", "--approach-kpa-per-s", "1e9"],
     "'--approach-kpa-per-s': 1e+09 kPa/s is faster than the set-point's slew limit (--max-rate-kpa-per-s, 500 kPa/s)"),
])
def test_a_track_too_slow_or_an_approach_beyond_the_slew_limit_is_refused(files, argv, message):
    res = CliRunner().invoke(main, [*argv, "/dev/null", "--calibration", files["calibration"],
                                    "--target-force-n", "0.15"])
    assert res.exit_code != 0 and "Traceback" not in res.output, res.output
    assert message in " ".join(res.output.split())


def test_a_zero_that_could_not_be_sent_after_a_normal_end_exits_1(single_board, files):
    # the board dies at 0.3 s; the run ends by its time (0.4 s, before the 1 s silence stop): its zero cannot go out
    board = Faulty(copy.deepcopy(single_board))
    with SimulatedDevice(board, rate_hz=RATE, faults=Faults(disconnect_after=FAULT_AT)) as dev:
        res = control_cli(dev.port, files, "--seconds", "0.4", "--silence-s", "1")
    assert res.exit_code == 1, res.output
    line = one_error_line(res)
    assert line.startswith("Error: control ended (duration reached) but set-point 0 could NOT be sent on line 0 (")
    assert "sent on every" not in res.output and board.received[-1][1] > 0


def test_a_pressure_outside_the_configs_range_leaves_the_finger_without_a_force(single_board, calibration_path):
    # the config's actuator model ends at 30 kPa; the loop may drive to 100 kPa: past 30 kPa the finger has no force
    import dataclasses

    narrow = dataclasses.replace(CONFIG, actuator=dataclasses.replace(CONFIG.actuator, pressure_range_pa=(0.0, 30e3)))
    proc = LiveProcessor(Calibration.load(calibration_path), narrow, load="contact", contact_s_m=S_C,
                         constraint="normal", bandwidth_hz=30.0)
    proc.warm_up()
    board = Faulty(copy.deepcopy(single_board))
    truth = Truth()
    with SimulatedDevice(board, rate_hz=RATE, truth=truth) as dev, Driver(dev.port) as driver:
        driver.start()
        with pytest.raises(ControlStop, match=r"^no force \(pressure_out_of_range\) for 10 ms") as info:
            run(driver, proc, PIController(0.15, max_pressure_pa=LIMIT_PA), max_pressure_pa=LIMIT_PA, seconds=2.0,
                safety=Safety(silence_s=1.0))
        board_caught_up(dev, driver)
    pressure = truth.column("pressure_pa")
    first = int(np.flatnonzero(pressure > 30e3)[0])  # the board's first frame beyond the model's range
    # stopped at the frame 10 ms after it, by the board's clock (the loop's frame count leaves out the block it
    # stopped in, which is long on a loaded machine)
    stopped_t_s = float(re.search(r"at t = ([\d.]+) s", str(info.value))[1])
    assert stopped_t_s - truth.t_us[first] * 1e-6 == pytest.approx(0.010, abs=1.5 / RATE)
    assert info.value.result.frames <= first + 30
    assert board.received[-1] == (0, 0.0) and truth.column("setpoint_pa")[-1] == 0.0


# --------------------------------------------------------------------------- signals, deaf boards, refusals

CLI = [sys.executable, "-c", "from bendsense.cli import main; main()"]


def wait_for(condition, timeout_s):
    end = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < end:
        time.sleep(0.005)
    return condition()


def test_a_closed_terminal_sighup_zeroes_every_line_and_exits_129(single_board, files):
    # the board has no watchdog (Faulty has no release): a zero on its line can only come from the command itself
    board = Faulty(copy.deepcopy(single_board))
    with SimulatedDevice(board, rate_hz=RATE) as dev:
        proc = subprocess.Popen([*CLI, "control", dev.port, "--calibration", files["calibration"], "--target-force-n",
                                 "0.15", "--load", "contact", "--contact-s-m", str(S_C), "--silence-s", "1"],
                                stderr=subprocess.PIPE, text=True)
        try:
            assert wait_for(lambda: board.received and board.received[-1][1] > 20e3, 60.0)
            proc.send_signal(signal.SIGHUP)  # the terminal (or the ssh session) closed
            err = proc.communicate(timeout=60)[1]  # a bound on a busy machine, not an expected time
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        board_caught_up(dev)  # the zeros reach the board
    assert proc.returncode == 129, err
    assert err.splitlines()[-1] == "Interrupted (SIGHUP): set-point 0 sent on every pressure line (0)", err
    assert board.received[-1] == (0, 0.0) and board.board.regulators.setpoint_pa[0] == 0.0
    assert dev.stats.watchdog_trips == 0


def test_a_second_ctrl_c_while_control_zeros_waits_for_every_zero(gripper_board, files, monkeypatch):
    # Ctrl-C mid-grasp, and again while the zeros go out (after line 0's): lines 1 and 2 still get theirs
    board = Faulty(copy.deepcopy(gripper_board))
    send, send_all = Driver.send_setpoint, Driver.send_setpoints
    presses = []

    def send_setpoints(self, setpoints, *, check_line=True, drain=True):  # the loop's: every line's of a block
        for line, pressure_pa in setpoints.items():
            if pressure_pa > 20e3 and not presses:
                presses.append(line)
                os.kill(os.getpid(), signal.SIGINT)
        return send_all(self, setpoints, check_line=check_line, drain=drain)

    def send_setpoint(self, line, pressure_pa, *, check_line=True):  # the zeros at the end, line by line
        if pressure_pa == 0.0 and len(presses) == 1 and line == 1:
            presses.append(line)
            os.kill(os.getpid(), signal.SIGINT)
        return send(self, line, pressure_pa, check_line=check_line)

    monkeypatch.setattr(Driver, "send_setpoints", send_setpoints)
    monkeypatch.setattr(Driver, "send_setpoint", send_setpoint)
    with SimulatedDevice(board, rate_hz=RATE, n_channels=GRIPPER_CHANNELS) as dev:
        res = CliRunner().invoke(main, ["control", dev.port, "--config", files["gripper"], "--calibration",
                                        files["calibration"], "--target-force-n", "0.15", "--load", "contact",
                                        "--contact-s-m", str(S_C), "--seconds", "5", "--silence-s", "1"])
        board_caught_up(dev)  # the zeros reach the board
    assert len(presses) == 2, res.output
    assert res.exit_code == 130, res.output
    assert res.output.splitlines()[-1] == "Interrupted (SIGINT): set-point 0 sent on every pressure line (0, 1, 2)"
    assert max(v for _, v in board.received) > 10e3 and board.last() == {0: 0.0, 1: 0.0, 2: 0.0}
    assert list(board.board.regulators.setpoint_pa) == [0.0, 0.0, 0.0] and dev.stats.watchdog_trips == 0


def test_a_board_that_ignores_its_setpoints_is_said_to_keep_its_pressure(files):
    # a plain sim-device: its scenario sets the pressure (0 to 100 kPa and back every 5 s), each SETPOINT "ignored"
    with SimulatedDevice(rate_hz=RATE) as dev:
        res = control_cli(dev.port, files, "--seconds", "0.5", "--silence-s", "1")
    stats = dev.stats
    assert stats.setpoints == 0 and stats.commands > 10  # the board's own counters: it applied none of them
    assert res.exit_code == 1, res.output
    line = one_error_line(res)
    found = re.fullmatch(r"Error: control ended \(duration reached\) but set-point 0 sent on every pressure line "
                         r"\(0\); line 0 did not fall: ([\d.]+) kPa after 0\.5\d* s", line)
    assert found, line
    assert 5 < float(found.group(1)) < 100  # the scenario's ramp, 1 s in (the run, then the watch)


def test_a_board_that_holds_a_line_above_its_setpoints_stops_the_loop(single_board, calibration_path):
    # from frame 300 the board reads 60 kPa whatever it is told (a stuck regulator); the controller holds 20 kPa
    proc = LiveProcessor(Calibration.load(calibration_path), CONFIG, load="contact", contact_s_m=S_C,
                         constraint="normal", bandwidth_hz=30.0)
    proc.warm_up()
    board = Faulty(copy.deepcopy(single_board), FAULT_AT, lambda p: 60e3)
    truth = Truth()

    def hold_20_kpa(block):
        return {0: 20e3}

    with SimulatedDevice(board, rate_hz=RATE, truth=truth) as dev, Driver(dev.port) as driver:
        driver.start()
        t0 = time.monotonic()
        with pytest.raises(ControlStop, match=r"^line 0 reads 60 kPa at seq (\d+), above every set-point sent to it "
                                              r"for 0\.25 s \(at most 20 kPa, \+5 kPa\): the board does not follow its "
                                              "set-points") as info:
            run(driver, proc, hold_20_kpa, max_pressure_pa=LIMIT_PA, seconds=2.0, safety=Safety(silence_s=1.0))
        ran = time.monotonic() - t0
        board_caught_up(dev, driver)
    result = info.value.result
    # the host has sent 20 kPa for longer than 0.25 s: the first frame that reads 60 kPa stops it, before processing
    assert info.match(rf"at seq {truth.seq[FAULT_AT]},") and result.frames <= FAULT_AT and ran < 1.5
    assert board.received[-1] == (0, 0.0) and truth.column("setpoint_pa")[-1] == 0.0
    assert result.high == (0,) and result.zeros[0].pressure_pa == 60e3 and 0.5 <= result.zeros[0].after_s < 0.7
    # the watch's length, as timed on this machine (0.5 s and a scheduler's few ms), in two digits
    assert re.search(r"; line 0 did not fall: 60 kPa after 0\.[56]\d? s$", zero_report(result))


@pytest.mark.parametrize("constraint", ["direction", "none"])
def test_a_constraint_that_cannot_start_from_rest_is_refused_before_the_board_is_driven(single_board, files,
                                                                                       constraint):
    board = Faulty(copy.deepcopy(single_board))
    with SimulatedDevice(board, rate_hz=RATE) as dev:
        res = control_cli(dev.port, files, "--constraint", constraint)
    assert res.exit_code == 2, res.output
    assert one_error_line(res).startswith(f"Error: Invalid value for '--constraint': {constraint} leaves the load of "
                                          "a finger at rest (straight, no pressure) undetermined")
    assert board.received == [] and dev.stats.commands == 0 and dev.stats.hellos == 0
