"""A simulated board whose finger is not the config's: sim-device's model-error options.

The grasp board of ``sim-device --object rigid --ei-error 0.3`` against an EI-exact finger,
and the options' checks. The free board with ``--k0-error`` against the independent
forward model is in tests/identify/test_port.py (it shares that module's boards).
"""

import csv
import os
import time

import numpy as np
import pytest
from click.testing import CliRunner

import bendsense
from bendsense.cli import main
from bendsense.cli.sim import grasp_board
from bendsense.device.driver import Driver
from bendsense.device.simdevice import SimulatedDevice
from bendsense.sim.actuator import SimulatedActuator
from bendsense.sim.grasp import FingerGrasp, GraspObject
from bendsense.sim.truth import TruthWriter, truth_columns

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")
CONFIG = bendsense.load_config()
RATE = 500.0


def truth_rows(path):
    with open(path, encoding="utf-8") as fh:
        assert fh.readline().startswith("# bendsense")
        return [r for r in csv.DictReader(fh) if None not in r.values()]


def hold(port, pressure_pa, settle_s=0.25, seconds=0.3):
    """Hold line 0 at ``pressure_pa``; the readings after it settled, then set-point 0."""
    with Driver(port) as driver:
        driver.start()
        driver.send_setpoint(0, pressure_pa)
        time.sleep(settle_s)
        driver.get_batch(timeout=0.01, max_items=100_000)  # the ramp
        readings, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            driver.send_heartbeat()
            readings += driver.get_batch(timeout=0.05)
        driver.send_setpoint(0, 0.0)
        time.sleep(0.05)
    return readings


def test_a_board_whose_ei_is_30_percent_high_presses_harder_on_a_rigid_object(tmp_path):
    # the same rigid object (touched at 60 kPa, at s_c = 0.10 m) and pressure: a stiffer finger pushes harder
    options = {"object_kind": "rigid", "object_s_m": (0.10,), "object_touch_kpa": (60.0,), "max_pressure_kpa": 80.0}
    stiff = grasp_board(options, rate_hz=RATE, seed=0, adc_bits=12, errors={"ei_error": 0.3})
    exact = FingerGrasp(SimulatedActuator.from_config(CONFIG), GraspObject(0.10, 60e3), max_pressure_pa=80e3,
                        step_pa=40e3)
    path = tmp_path / "truth.csv"
    truth = TruthWriter(path, truth_columns())
    with SimulatedDevice(stiff, rate_hz=RATE, truth=truth) as dev:
        readings = hold(dev.port, 80e3)
    truth.close()
    rows = [r for r in truth_rows(path) if abs(float(r["pressure_pa"]) - 80e3) < 1.0]
    assert len(rows) > 20 and readings
    force = np.hypot([float(r["fx_n"]) for r in rows], [float(r["fy_n"]) for r in rows])
    reference = float(exact.solve([80e3]).contact_n[0])
    # a rigid object holds the finger's point where it is: the force scales with EI (gravity aside)
    ratio = force / reference
    print(f"EI +30 %: {np.mean(force) * 1e3:.1f} mN vs {reference * 1e3:.1f} mN EI-exact (ratio {np.mean(ratio):.3f})")
    assert np.all((ratio > 1.2) & (ratio < 1.4)), ratio
    assert reference > 0.05


@pytest.mark.parametrize(("args", "hint"), [
    (["--k0-error", "8"], "--k0-error"),
    (["--ei-error", "-1"], "--ei-error"),
    (["--base-rotation", "nan"], "--base-rotation"),
    (["--hysteresis-kpa", "-2"], "--hysteresis-kpa"),
    (["--source", "ramp", "--k0-error", "0.1"], "--k0-error"),
    (["--replay", ".", "--ei-error", "0.1"], "--ei-error"),
])
def test_sim_device_model_errors_are_checked(args, hint):
    res = CliRunner().invoke(main, ["sim-device", "--seconds", "0.1", *args])
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert res.exit_code == 2 and len(errors) == 1 and hint in res.output, res.output
    assert "Traceback" not in res.output


def test_a_board_with_pressure_play_bends_as_the_pressure_it_came_from():
    # play of 10 kPa: held at 50 kPa after 60 kPa, the finger bends as at 55 kPa (the play's upper edge)
    from bendsense.sim.gripper import GraspBoard

    def settled(board, setpoints):
        k = 0
        for p in setpoints:
            board.setpoint(0, p)
            for _ in range(250):  # 0.5 s at 500 Hz: 20 time constants of the regulator
                pressure, counts, _ = board(k)
                k += 1
        return pressure, counts

    play = GraspBoard(CONFIG, [None], rate_hz=RATE, noise_counts=0.0, step_pa=5e3, hysteresis_pa=10e3)
    plain = GraspBoard(CONFIG, [None], rate_hz=RATE, noise_counts=0.0, step_pa=5e3)
    pressure, counts = settled(play, [60e3, 50e3])
    assert pressure == pytest.approx(50e3, abs=1.0)  # the reading: the regulator's pressure
    assert np.array_equal(counts, settled(plain, [55e3])[1])
    assert not np.array_equal(counts, settled(plain, [50e3])[1])
