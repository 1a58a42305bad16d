"""Helpers shared by the tests: data made in the test, independently of the code under test.

``from helpers import ...`` (the tests directory is on ``sys.path``, as for
``forward_model``). Fixtures built on these live in ``conftest.py``.
"""

import functools
import io
import logging
import os
import subprocess
import time
import traceback

import numpy as np

from bendsense import load_config, output
from bendsense.calibration import Calibration

CONFIG = load_config()
SENSOR = CONFIG.sensor
N = SENSOR.n_segments
ODD = np.arange(N) % 2 == 0  # channels 1, 3, ... (1-based)
GAIN = 2e-6  # shift per signal unit of the linear test calibration [m]


def linear_calibration(gain=GAIN, *, offset=None, delta_a=3000.0, noise_std=1.0, sensor=SENSOR):
    """S_i = ±gain · ΔA_i (odd channels +, even −): an exactly invertible calibration.

    ``offset`` defaults to 2000 + 10 i; ``noise_std`` (per channel) and ``sensor`` may be None.
    """
    return Calibration(
        offset=2000.0 + 10.0 * np.arange(N) if offset is None else offset,
        coefficients_odd=[0.0, gain],
        coefficients_even=[0.0, -gain],
        degree=1,
        delta_a_range_odd=(-delta_a, delta_a),
        delta_a_range_even=(-delta_a, delta_a),
        noise_std=None if noise_std is None else np.full(N, noise_std),
        sensor=sensor,
    )


def shifts_for(kappa):
    """Total shifts S_i = d Σ_{j≤i} κ_j l_j [m] (paper eq. 3–4), independent of bendsense.shape.pcc."""
    return SENSOR.strip_gap_m * np.cumsum(np.asarray(kappa) * SENSOR.lengths_m, axis=-1)


def signals_for(kappa, calibration, gain=GAIN):
    """The signals that ``linear_calibration(gain)`` turns into the curvatures ``kappa`` [1/m]."""
    shifts = shifts_for(kappa)
    return calibration.offset + np.where(ODD, shifts / gain, -shifts / gain)


def curvatures_for(shifts):
    """Segment curvatures [1/m] of total shifts [m] on the paper's sensor."""
    from bendsense.shape.pcc import shifts_to_curvatures

    return shifts_to_curvatures(shifts, SENSOR.lengths_m, SENSOR.strip_gap_m)


@functools.cache
def _actuator():
    from bendsense.sim.actuator import SimulatedActuator

    return SimulatedActuator.from_config(CONFIG, noise_counts=0.0)


def loaded_curvatures(pressure_pa, force_n):
    """Segment curvatures (frames, N) [1/m] of the simulated actuator (beam model, no noise)."""
    return _actuator().frames(pressure_pa, force_n, noise=False).curvature_per_m


def hold_output(path, ready, release, timeout_s):
    """Hold ``path`` as an output (in another process) from ``ready`` until ``release``."""
    with output.reserve([output.directory(path)]):
        ready.set()
        release.wait(timeout_s)


class Listening:
    """A simulated board, keeping every SETPOINT it receives (also after it stopped streaming): its own record."""

    def __init__(self, board):
        self.board, self.received = board, []

    def setpoint(self, line, pressure_pa):
        self.received.append((line, pressure_pa))
        return self.board.setpoint(line, pressure_pa)

    def release(self):
        self.board.release()

    def __call__(self, k):
        return self.board(k)


def board_caught_up(dev, driver=None, *, frames=30, timeout_s=60.0):
    """Wait until the simulated board ``dev`` has taken every command sent to it so far and, if it streams, made
    ``frames`` frames after them (their truth carries the set-points it then holds).

    An acknowledgement, not a guess of the clock: a HELLO_REQUEST written after the commands (through ``driver``,
    the open connection they went through, or a new one after a command that closed its own) is answered after
    them, and the frames are counted by the board itself. On a loaded machine the board's thread may not run for a
    while, and a fixed sleep (30 ms: 30 frames at 1 kHz) may see none of it. A board whose port is closed (it died,
    or was disconnected) takes nothing more: no wait.
    """
    from bendsense.device.driver import Driver

    if dev.stats.disconnected:
        return
    if driver is not None:
        driver.request_hello(timeout_s=timeout_s)
    else:
        with Driver(dev.port, hello_timeout_s=timeout_s):
            pass
    end, deadline = dev.stats.generated + frames, time.monotonic() + timeout_s
    while dev.streaming and not dev.finished.is_set() and dev.stats.generated < end:  # (finished: it makes no more)
        assert time.monotonic() < deadline, f"the board made {frames} frames in {timeout_s} s"
        time.sleep(0.002)


def run_cli(args, *, cwd=None) -> subprocess.CompletedProcess:
    """``bendsense ARGS`` called in this process (click's ``CliRunner``: the console script's ``main``), in ``cwd``.

    As from a process of its own: the exit code (of its ``SystemExit``), stdout, and stderr with what the command
    logged (``LEVEL: message``, its format) and the traceback of an exception that escaped it (exit code 1). For
    the tests whose subject is not the process (its signals, its exit, a fresh interpreter): no interpreter start
    and no load of the compiled kernels per command.
    """
    from click.testing import CliRunner

    from bendsense.cli import main

    args = [str(a) for a in args]
    logged = io.StringIO()
    handler = logging.StreamHandler(logged)
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    root, old = logging.getLogger(), os.getcwd()
    root.addHandler(handler)
    try:
        if cwd is not None:
            os.chdir(cwd)
        result = CliRunner().invoke(main, args)
    finally:
        os.chdir(old)
        root.removeHandler(handler)
    stderr = logged.getvalue() + result.stderr
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        stderr += "".join(traceback.format_exception(result.exception))
    return subprocess.CompletedProcess(["bendsense", *args], result.exit_code, result.stdout, stderr)
