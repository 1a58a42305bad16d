"""bendsense.control on the simulated grasp board over a pseudo-terminal, scored against the simulator's truth.

The board (bendsense.sim.gripper.GraspBoard: a regulator with a 25 ms lag and a rigid
object that the finger touches at s_c = 0.10 m from 40 kPa on) writes its truth for
every frame it generates; the loop runs the real driver, processor and controller.
"""

import copy
import csv
import os
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from helpers import Listening, board_caught_up

import bendsense
from bendsense.calibration import Calibration
from bendsense.control import CONTROL_LOG, ControlRecording, ControlStop, PIController, Safety, run
from bendsense.device.driver import Driver
from bendsense.device.simdevice import Faults, SimulatedDevice
from bendsense.pipeline import LiveProcessor
from bendsense.sim.grasp import GraspObject
from bendsense.sim.gripper import GraspBoard

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals"),
              pytest.mark.realtime]
CONFIG = bendsense.load_config()
S_C, TOUCH_PA, RATE = 0.10, 40e3, 1000.0
LIMIT_PA = 100e3


class Truth:
    """The simulator's truth of every frame generated, by frame (what ``sim-device --truth`` writes)."""

    def __init__(self):
        self.rows = []

    def write(self, seq, t_us, truth):
        self.rows.append((seq, t_us, truth))

    def flush(self):
        pass

    def column(self, name):
        return np.array([r[2][name] for r in self.rows])

    @property
    def t_s(self):
        return np.array([r[1] for r in self.rows]) * 1e-6

    @property
    def force_n(self):
        return np.hypot(self.column("fx_n"), self.column("fy_n"))


@pytest.fixture(scope="module")
def processor(calibration_path):
    proc = LiveProcessor(Calibration.load(calibration_path), CONFIG, load="contact", contact_s_m=S_C,
                         constraint="normal", bandwidth_hz=30.0)
    proc.warm_up()
    return proc


@pytest.fixture(scope="module")
def fresh_board():
    return GraspBoard(CONFIG, [GraspObject(S_C, TOUCH_PA)], rate_hz=RATE, seed=0)


@pytest.fixture
def board(fresh_board):
    return copy.deepcopy(fresh_board)  # its regulator and noise from the start; the tables made once


def session(board, processor, controller, *, drop=0.0, after=None, source=None, **kw):
    """Run the loop on the board; returns (result or the exception, truth).

    The silence limit is 1 s unless a test sets it: a loaded machine may hold the board's
    thread back for 0.1 s, which is not what these tests are about.
    """
    kw.setdefault("safety", Safety(silence_s=1.0))
    processor.reset()
    truth = Truth()
    with SimulatedDevice(source or board, rate_hz=RATE, truth=truth, faults=Faults(drop=drop, seed=3)) as dev, \
            Driver(dev.port) as driver:
        driver.start()
        try:
            out = run(driver, processor, controller, max_pressure_pa=kw.pop("max_pressure_pa", LIMIT_PA), **kw)
        except (ControlStop, KeyboardInterrupt) as err:
            out = err
        board_caught_up(dev, driver)  # frames after the stop: their truth carries the set-point the board holds
        if after is not None:
            after(driver)
    return out, truth


def test_the_loop_holds_015_n_and_records_it(board, processor, tmp_path):
    """The default controller (ModelController) on the board over a pseudo-terminal: the true force does not
    overshoot 0.15 N by more than 15 mN at the touch and holds it within 10 mN (DESIGN.md section 5). The loop
    runs until the tracked force held for 0.3 s: an event, not a guess of how long a loaded machine takes."""
    from bendsense.control import ModelController

    controller = ModelController(0.15, CONFIG, max_pressure_pa=LIMIT_PA, contact_s_m=S_C)
    stop, held_s = threading.Event(), [0.0]

    def on_block(block, setpoints):
        held_s[0] = held_s[0] + len(block) / RATE if np.all(np.abs(controller.last.force_n - 0.15) <= 0.005) else 0.0
        if held_s[0] >= 0.3:
            stop.set()

    processor.reset()
    truth = Truth()
    out = tmp_path / "grasp"
    with SimulatedDevice(board, rate_hz=RATE, truth=truth) as dev, Driver(dev.port) as driver:
        rec = ControlRecording(driver, out, config=CONFIG, meta={"command": "test"})
        driver.start()
        result = run(driver, processor, controller, max_pressure_pa=LIMIT_PA, seconds=60.0, stop=stop,
                     recording=rec, safety=Safety(silence_s=1.0), on_block=on_block)
        board_caught_up(dev, driver)
    assert result.outcome == "stopped", "the force was never held for 0.3 s"
    force, setpoint = truth.force_n, truth.column("setpoint_pa")
    last = np.flatnonzero(setpoint > 0)[-1]
    assert force.max() <= 0.15 + 0.015  # the touch: no overshoot beyond 15 mN
    assert np.all(np.abs(force[last - 250:last] - 0.15) <= 0.01)  # DESIGN section 5: steady error <= 10 mN
    assert setpoint.max() <= LIMIT_PA and truth.column("pressure_pa").max() <= LIMIT_PA
    assert setpoint[-1] == 0.0  # let go at the end
    # the session: every frame in frames.bin and in control.csv, the results beside
    rec_session = bendsense.read_session(out)
    assert len(rec_session) == result.frames
    with open(out / CONTROL_LOG, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == result.frames
    assert list(rows[0])[:8] == ["t_s", "seq", "host_s", "normal_force_n", "normal_force_std_n", "contact_s_m",
                                 "target_force_n", "status"]
    by_seq = {r[0]: r[2] for r in truth.rows}
    late = [r for r in rows if float(r["t_s"]) > 0.6]
    est = np.array([float(r["normal_force_n"]) for r in late])
    true = np.array([np.hypot(by_seq[int(r["seq"])]["fx_n"], by_seq[int(r["seq"])]["fy_n"]) for r in late])
    assert np.all(np.abs(est - true) < 0.005)
    sent = np.array([float(r["setpoint_pa"]) for r in rows])
    measured = np.array([float(r["pressure_pa"]) for r in rows])
    np.testing.assert_allclose(measured, np.array([by_seq[int(r["seq"])]["pressure_pa"] for r in rows]), atol=1.0)
    assert sent.max() <= LIMIT_PA and float(rows[0]["contact_s_m"]) == S_C
    assert (out / "results.csv").is_file()
    assert rec_session.meta.get("outcome") == "stopped"


def test_a_setpoint_beyond_the_limit_is_never_sent(board, processor):
    stop = threading.Event()
    asked = []

    def greedy(block):  # a user's controller that asks far too much
        asked.append(block.t_s[-1])
        if len(asked) > 300:
            stop.set()
        return {0: 500e3}

    result, truth = session(board, processor, greedy, max_pressure_pa=45e3, stop=stop)
    assert result.outcome == "stopped" and result.clipped == result.blocks
    assert truth.column("setpoint_pa").max() == 45e3
    assert truth.column("pressure_pa").max() <= 45e3
    assert truth.column("setpoint_pa")[-1] == 0.0


def test_the_loop_reads_the_port_itself_so_a_blocks_frames_come_in_one_read(board, processor):
    """A loop busy 3 ms a block at 1 kHz: the frames that arrived meanwhile come in the loop's one read of the port
    (the reader thread, free while the loop sleeps, would have read each as it came: as many reads as frames), and
    every frame the board sent before the stop reached the loop, in order."""
    stop, seqs = threading.Event(), []

    def on_block(block, setpoints):
        seqs.extend(block.seq)
        time.sleep(0.003)
        if len(seqs) >= 400:
            stop.set()

    result, truth = session(board, processor, PIController(0.15, max_pressure_pa=LIMIT_PA), stop=stop,
                            on_block=on_block)
    assert result.outcome == "stopped"
    # the first block: what the reader thread had queued before the loop took the port; a block held up beyond
    # Driver.here_stall_s (a loaded machine) has the thread read for it
    assert np.median(result.block_frames) >= 2 and np.mean(result.block_reads[1:] == 1) >= 0.9
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))


def test_lost_frames_stop_the_loop(board, processor):
    pi = PIController(0.15, max_pressure_pa=LIMIT_PA)
    err, truth = session(board, processor, pi, drop=0.05, seconds=5.0, safety=Safety(max_lost_frames=10, silence_s=1.0))
    assert isinstance(err, ControlStop) and "frames lost" in err.reason
    assert truth.column("setpoint_pa")[-1] == 0.0 and truth.t_s[-1] < 2.0



def test_a_board_that_falls_silent_stops_the_loop(board, processor):
    pi = PIController(0.15, max_pressure_pa=LIMIT_PA)
    processor.reset()
    source = Listening(board)
    with SimulatedDevice(source, rate_hz=RATE, max_frames=300) as dev, Driver(dev.port) as driver:
        driver.start()
        with pytest.raises(ControlStop, match="no frame from the board for"):
            run(driver, processor, pi, max_pressure_pa=LIMIT_PA, seconds=5.0, safety=Safety(silence_s=0.05))
        board_caught_up(dev, driver)
    assert max(p for _, p in source.received) > 0 and source.received[-1] == (0, 0.0)


class Bent:
    """The board with one channel off by 400 counts from frame 300 on: a shape no beam makes (a persistent misfit)."""

    def __init__(self, board):
        self.board = board

    def setpoint(self, line, pressure_pa):
        return self.board.setpoint(line, pressure_pa)

    def __call__(self, k):
        p, counts, truth = self.board(k)
        if k >= 300:
            counts = counts.copy()
            counts[7] += 400
        return p, counts, truth


def test_a_model_misfit_on_the_controlled_finger_stops_the_loop(board, processor):
    pi = PIController(0.15, max_pressure_pa=LIMIT_PA)
    err, truth = session(board, processor, pi, seconds=5.0, source=Bent(board))
    assert isinstance(err, ControlStop) and "model_misfit" in err.reason
    assert truth.column("setpoint_pa")[-1] == 0.0
    # stopped within the first windows after the fault, by the board's clock (truth row k is frame k; the loop's
    # frame count leaves out the block it stopped in, which is long on a loaded machine)
    stopped_t_s = float(re.search(r"at t = ([\d.]+) s", str(err))[1])
    assert 0.0 < stopped_t_s - truth.t_s[300] < 0.2


def test_not_identifiable_on_the_controlled_finger_stops_the_loop(board, calibration_path):
    # both force components free (constraint none): a straight finger does not determine the load along its
    # axis, so the frames at rest are not_identifiable and the loop must not act on them
    proc = LiveProcessor(Calibration.load(calibration_path), CONFIG, constraint="none", bandwidth_hz=30.0)
    proc.warm_up()
    err, truth = session(board, proc, PIController(0.15, max_pressure_pa=LIMIT_PA), seconds=5.0)
    assert isinstance(err, ControlStop) and "not_identifiable for 10 ms" in err.reason
    assert truth.column("setpoint_pa")[-1] == 0.0 and err.result.frames < 200


def test_ctrl_c_sets_every_line_to_zero(board, processor):
    pi = PIController(0.15, max_pressure_pa=LIMIT_PA)

    def on_block(block, setpoints):
        if block.t_s[-1] > 0.3:
            raise KeyboardInterrupt

    err, truth = session(board, processor, pi, on_block=on_block)
    assert isinstance(err, KeyboardInterrupt)
    setpoint = truth.column("setpoint_pa")
    assert setpoint.max() > TOUCH_PA and setpoint[-1] == 0.0


CLI = [sys.executable, "-c", "from bendsense.cli import main; main()"]


def test_sigterm_ends_the_command_with_every_line_at_zero(board, calibration_path, tmp_path):
    truth = Truth()
    out = tmp_path / "s"
    with SimulatedDevice(board, rate_hz=RATE, truth=truth) as dev:
        proc = subprocess.Popen([*CLI, "control", dev.port, "--calibration", str(calibration_path),
                                 "--target-force-n", "0.15", "--load", "contact", "--contact-s-m", str(S_C),
                                 "--silence-s", "1", "-o", str(out)], stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (truth.rows and truth.rows[-1][2]["setpoint_pa"] > 50e3):
            time.sleep(0.05)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
        board_caught_up(dev)
    assert proc.returncode == 143, err
    assert f"Interrupted (SIGTERM): set-point 0 sent on every pressure line (0); the session is in {out}" in err
    assert truth.column("setpoint_pa").max() > 50e3 and truth.column("setpoint_pa")[-1] == 0.0
    assert len(bendsense.read_session(out)) > 100 and (out / CONTROL_LOG).is_file()


def test_a_gripper_holds_with_two_fingers_and_lets_go_of_every_line(calibration_path, tmp_path):
    """Two fingers, each by its model (ModelController), hold 0.15 N; the loop runs until both held their force
    for 0.3 s (an event, not a guess of how long a loaded machine takes), then every line lets go."""
    from bendsense.control import Grasp, ModelController
    from bendsense.pipeline.gripper import GripperProcessor
    from bendsense.sim import gripper_config

    gripper = gripper_config(3)
    board = GraspBoard(gripper, [GraspObject(S_C, p) for p in (40e3, 45e3, 35e3)], rate_hz=RATE, seed=0)
    proc = GripperProcessor(Calibration.load(calibration_path), gripper, load="contact", contact_s_m=S_C,
                            constraint="normal", bandwidth_hz=30.0)
    proc.warm_up()
    grasp = Grasp([ModelController(0.15, f.config, line=f.pressure_line, finger=f.name, max_pressure_pa=LIMIT_PA,
                                   contact_s_m=S_C)
                   for f in gripper.fingers[:2]])  # the middle finger is not controlled: its line is held at 0
    truth, out, stop, held_s = Truth(), tmp_path / "grip", threading.Event(), [0.0]

    def on_block(block, setpoints):
        steady = all(np.all(np.abs(c.last.force_n - 0.15) <= 0.005) for c in grasp.controllers)
        held_s[0] = held_s[0] + len(next(iter(block.values()))) / RATE if steady else 0.0
        if held_s[0] >= 0.3:
            stop.set()

    with SimulatedDevice(board, rate_hz=RATE, truth=truth, n_channels=board.n_channels) as dev, \
            Driver(dev.port) as driver:
        rec = ControlRecording(driver, out, config=gripper, fingers=gripper.names)
        driver.start()
        result = run(driver, proc, grasp, max_pressure_pa=LIMIT_PA, seconds=60.0, stop=stop, recording=rec,
                     safety=Safety(silence_s=1.0), on_block=on_block)
        board_caught_up(dev, driver)
    assert stop.is_set(), "the fingers never held their force for 0.3 s"
    assert result.lines == (0, 1, 2) and result.held == (2,)
    assert truth.column("line2_setpoint_pa").max() < 1e3  # held from the first block, not the board's profile
    for k, name in enumerate(gripper.names):
        setpoint = truth.column(f"line{k}_setpoint_pa")
        assert setpoint[-1] == 0.0  # every line of the board let go, the uncontrolled one too
        if k < 2:
            force = np.hypot(truth.column(f"{name}_fx_n"), truth.column(f"{name}_fy_n"))
            held = np.flatnonzero(setpoint > 0)[-1]
            assert np.all(np.abs(force[held - 150:held] - 0.15) <= 0.01)
    with open(out / CONTROL_LOG, newline="") as fh:
        header = next(csv.reader(fh))
    assert header == ["t_s", "seq", "host_s",
                      *(f"{n}_{c}" for n in ("thumb", "index") for c in ("normal_force_n", "normal_force_std_n",
                                                                         "contact_s_m", "target_force_n", "status")),
                      *(f"line{k}_{c}" for k in range(3) for c in ("setpoint_pa", "pressure_pa"))]
    assert all((out / name / "results.csv").is_file() for name in gripper.names)
    assert len(bendsense.read_session(out)) == result.frames


def test_a_safety_stop_is_one_line_and_exit_1(board, calibration_path, tmp_path):
    from click.testing import CliRunner

    from bendsense.cli import main

    truth = Truth()
    with SimulatedDevice(board, rate_hz=RATE, truth=truth, faults=Faults(drop=0.05, seed=3)) as dev:
        res = CliRunner().invoke(main, ["control", dev.port, "--calibration", str(calibration_path),
                                        "--target-force-n", "0.15", "--load", "contact", "--contact-s-m", str(S_C),
                                        "--silence-s", "1", "-o", str(tmp_path / "s")])
        board_caught_up(dev)
    assert res.exit_code == 1, res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "Traceback" not in res.output
    assert errors[0].startswith("Error: control stopped: ") and "frames lost within 1 s" in errors[0]
    assert errors[0].endswith(f"set-point 0 sent on every pressure line (0); the session is in {tmp_path / 's'}")
    assert truth.column("setpoint_pa")[-1] == 0.0
    assert bendsense.read_session(tmp_path / "s").meta["outcome"].startswith("safety stop: ")
