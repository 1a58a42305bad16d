"""``identify free-bending --port``: a free sweep driven on a live board, recorded and fitted.

The boards are simulated boards whose actuator's K0 is 8 % above or below the config's
(``bendsense sim-device --k0-error 0.08`` in the background, and the same board with -0.08
in this process), started once for the module; the identified K0(P) is
scored against the true one computed independently (tests/forward_model.py: its own
quadrature of the free-bending model, times the board's ``1 + k0_error``), and the
board's truth file says what the line did.
"""

import csv
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner
from forward_model import forward, free_bending_k0
from helpers import Listening, board_caught_up

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.device.driver import Driver
from bendsense.device.simdevice import SimulatedDevice, scripted_board
from bendsense.mechanics.actuator import FreeBendingModel
from bendsense.sim.truth import TruthWriter, truth_columns

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")
CONFIG = bendsense.load_config()
CLI = [sys.executable, "-c", "from bendsense.cli import main; main()"]
RATE = 50.0  # a slow board: 150 frames a sweep (the fit's covariance grows with the square of the frames)
SWEEP_S = 3.0
TOP_PA = 100e3  # the sweep's default top: 100 kPa


def truth_rows(path):
    with open(path, encoding="utf-8") as fh:
        assert fh.readline().startswith("# bendsense")
        return [r for r in csv.DictReader(fh) if None not in r.values() and r["pressure_pa"]]


@pytest.fixture(scope="module")
def boards(tmp_path_factory):
    """K0 +8 %: ``bendsense sim-device --k0-error 0.08`` in the background; K0 -8 %: its board in this process.

    Each with its truth file; the second is built while the first starts.
    """
    root = tmp_path_factory.mktemp("boards")
    high, low = root / "truth+0.08.csv", root / "truth-0.08.csv"
    proc = subprocess.Popen([*CLI, "sim-device", "--rate", str(RATE), "--k0-error", "0.08", "--truth", str(high)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    truth = None
    try:
        truth = TruthWriter(low, truth_columns())
        with SimulatedDevice(scripted_board(rate_hz=RATE, k0_error=-0.08, truth=True), rate_hz=RATE,
                             truth=truth) as dev:
            port = proc.stdout.readline().strip()
            assert port.startswith("/dev/"), proc.stderr.read()
            yield {0.08: (port, high), -0.08: (dev.port, low)}
    finally:
        proc.terminate()
        proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()
        if truth is not None:
            truth.close()


def identify(port, calibration_path, out, *extra):
    return CliRunner().invoke(main, ["identify", "free-bending", "--port", port, "--calibration",
                                     str(calibration_path), "-o", str(out), "--seconds", str(SWEEP_S), *extra])


@pytest.mark.parametrize("k0_error", [0.08, -0.08], ids=["K0+8%", "K0-8%"])
def test_identify_on_a_live_board_finds_its_k0_within_2_percent(boards, calibration_path, tmp_path, k0_error):
    port, truth = boards[k0_error]
    out = tmp_path / "fitted.yaml"
    started = len(truth_rows(truth))
    res = identify(port, calibration_path, out)
    assert res.exit_code == 0, res.output
    fitted = bendsense.load_config(out)
    # the true K0(P): the board's 1 + k0_error times the config's, by the forward model's own quadrature
    p = np.linspace(0.0, TOP_PA, 21)
    true = (1.0 + k0_error) * np.array([free_bending_k0(CONFIG, x) for x in p])
    got = FreeBendingModel.from_config(fitted).tip_curvature_per_m(p)
    prior = FreeBendingModel.from_config(CONFIG).tip_curvature_per_m(p)
    error = (got - true) / true.max()  # K0 is 0 at 0 kPa: errors relative to its top
    upper = p >= 0.2 * TOP_PA  # and relative to K0(P) itself from 20 kPa on
    relative = got[upper] / true[upper] - 1.0
    print(f"K0 {k0_error:+.0%}: identified K0(P) error max {np.max(np.abs(error)) * 100:.2f} % of K0(100 kPa), "
          f"max {np.max(np.abs(relative)) * 100:.2f} % of K0(P) over 20-100 kPa (prior "
          f"{np.max(np.abs(prior[upper] / true[upper] - 1)) * 100:.1f} %)")
    assert np.all(np.abs(error) <= 0.02)
    assert np.all(np.abs(relative) <= 0.02)
    assert out.read_text().splitlines()[1].startswith("# free-bending identified by bendsense from ")
    if k0_error > 0:  # the sweep is recorded beside OUTPUT; --session fits it again to the same config (once: slow)
        again = CliRunner().invoke(main, ["identify", "free-bending", "--session", str(tmp_path / "fitted-sweep"),
                                          "--calibration", str(calibration_path), "-o", str(tmp_path / "again.yaml")])
        assert again.exit_code == 0, again.output
        assert bendsense.load_config(tmp_path / "again.yaml").material == fitted.material
    # the board's truth: free all along, up to the top and back, and the line at 0 after the sweep
    time.sleep(0.1)
    rows = truth_rows(truth)[started:]
    setpoint = np.array([float(r["setpoint_pa"]) for r in rows])
    assert all(float(r["fx_n"]) == 0.0 == float(r["fy_n"]) for r in rows)
    assert setpoint.max() == pytest.approx(TOP_PA, abs=1.0) and setpoint[-1] == 0.0
    assert float(rows[-1]["pressure_pa"]) < 1e3


def test_a_held_setpoint_on_a_board_with_k0_8_percent_high_bends_more_than_the_config(boards, calibration_path):
    # sim-device --k0-error 0.08, free, line 0 held at 60 kPa: the host's shape against the config's model
    port, truth = boards[0.08]
    with Driver(port) as driver:
        driver.start()
        driver.send_setpoint(0, 60e3)
        time.sleep(0.25)
        driver.get_batch(timeout=0.01, max_items=100_000)  # the ramp
        readings, end = [], time.monotonic() + 0.4
        while time.monotonic() < end:
            readings += driver.get_batch(timeout=0.05)
        driver.send_setpoint(0, 0.0)
    pressure = np.array([r.sample.pressure_pa for r in readings], dtype=float)
    assert len(readings) >= 15 and np.all(np.abs(pressure - 60e3) < 300)  # the regulator holds the set-point
    counts = np.array([r.sample.adc for r in readings], dtype=float)
    shape = bendsense.reconstruct(counts, Calibration.load(calibration_path), CONFIG.sensor)
    measured = float(np.mean(np.sum(shape.curvature_per_m * CONFIG.sensor.lengths_m, axis=-1)))  # φ(L_N) [rad]
    # the independent beam (gravity included): the config's actuator and one whose K0 is 1.08 times it
    model = forward(CONFIG, 60e3, (0.0, 0.0)).angles_rad[-1]
    true = forward(CONFIG, 60e3, (0.0, 0.0), k0_scale=1.08).angles_rad[-1]
    print(f"tip angle at 60 kPa: measured {measured:.4f} rad, config's model {model:.4f}, true {true:.4f}")
    # K0 larger: the free actuator bends more than the config's model, by about what K0 adds
    assert measured - model > 0.8 * (true - model) > 0.05
    assert abs(measured - true) < 0.2 * (true - model)
    time.sleep(0.05)
    rows = [r for r in truth_rows(truth) if float(r["setpoint_pa"]) == 60e3]
    assert len(rows) >= 15 and all(float(r["fx_n"]) == 0.0 == float(r["fy_n"]) for r in rows)  # free: no force


def test_a_board_that_falls_silent_mid_sweep_is_let_go_and_nothing_is_written(calibration_path, tmp_path):
    # the board stops streaming after 1 s of the sweep (it still takes commands): the sweep stops, zeroes the line
    board = Listening(scripted_board(rate_hz=RATE, seed=0, k0_error=0.08))
    out = tmp_path / "fitted.yaml"
    with SimulatedDevice(board, rate_hz=RATE, max_frames=int(RATE)) as dev:
        res = identify(dev.port, calibration_path, out)
        board_caught_up(dev)  # the zero reaches the board
    assert res.exit_code == 1, res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "Traceback" not in res.output, res.output
    assert errors[0].startswith("Error: the sweep stopped: no frame from the board for "), errors[0]
    assert "set-point 0 sent on every pressure line (0)" in errors[0]
    assert errors[0].endswith(f"the frames so far are in {tmp_path / 'fitted-sweep'}; nothing written to {out}")
    # the board's own record: the line was up mid-sweep, and its last set-point is 0
    assert max(p for _, p in board.received) > 20e3 and board.received[-1] == (0, 0.0)
    assert not out.exists()
    assert len(bendsense.read_session(tmp_path / "fitted-sweep")) == int(RATE)


@pytest.mark.parametrize(("args", "hint"), [
    (["stiffness", "--port", "/dev/null"], "--port"),
    (["free-bending", "--port", "/dev/null", "--session", "."], "--port"),
    (["free-bending", "--session", ".", "--seconds", "3"], "--seconds"),
    (["free-bending", "--session", ".", "--max-pressure-kpa", "50"], "--max-pressure-kpa"),
    (["free-bending", "--port", "/dev/null"], "--calibration"),
    (["free-bending", "--port", "/dev/null", "--seconds", "0"], "--seconds"),
])
def test_identify_port_options_are_checked(args, hint, tmp_path):
    res = CliRunner().invoke(main, ["identify", *args, "-o", str(tmp_path / "out.yaml")])
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert res.exit_code == 2 and len(errors) == 1 and hint in res.output, res.output
    assert not (tmp_path / "out.yaml").exists() and not (tmp_path / "out-sweep").exists()


def test_a_pressure_limit_beyond_the_config_is_refused_before_the_board_is_driven(calibration_path, tmp_path):
    board = Listening(scripted_board(rate_hz=RATE, seed=0))
    with SimulatedDevice(board, rate_hz=RATE) as dev:
        res = identify(dev.port, calibration_path, tmp_path / "out.yaml", "--max-pressure-kpa", "250")
    assert res.exit_code == 2 and "beyond the config's actuator.pressure_range_pa" in res.output, res.output
    assert board.received == [] and not (tmp_path / "out.yaml").exists()


def test_ctrl_c_mid_sweep_zeroes_the_line_and_writes_nothing(calibration_path, tmp_path):
    board = Listening(scripted_board(rate_hz=RATE, seed=0))
    out = tmp_path / "fitted.yaml"
    with SimulatedDevice(board, rate_hz=RATE) as dev:
        proc = subprocess.Popen([*CLI, "identify", "free-bending", "--port", dev.port, "--calibration",
                                 str(calibration_path), "-o", str(out), "--seconds", "20"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            end = time.monotonic() + 60.0
            while time.monotonic() < end and not any(p > 10e3 for _, p in board.received):
                time.sleep(0.05)
            assert proc.poll() is None and any(p > 10e3 for _, p in board.received)  # mid-sweep
            proc.send_signal(signal.SIGINT)
            _, stderr = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    assert proc.returncode == 130, stderr
    assert stderr.splitlines()[-1] == (f"Interrupted (SIGINT): set-point 0 sent on every pressure line (0); the frames "
                                       f"so far are in {tmp_path / 'fitted-sweep'}; nothing written to {out}"), stderr
    assert board.received[-1] == (0, 0.0) and not out.exists()
