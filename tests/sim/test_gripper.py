"""The simulated gripper board on a pseudo-terminal: version-2 SAMPLEs, SETPOINTs, the truth file, sim-device."""

import csv
import math
import os
import re
import select
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from bendsense.cli import main
from bendsense.config import load_config
from bendsense.device import SimulatedDevice, ramp_source
from bendsense.sim.gripper import (
    DEFAULT_CLOSE_PA,
    DEFAULT_TOUCH_PRESSURE_PA,
    GraspBoard,
    Regulation,
    default_objects,
    gripper_config,
)
from bendsense.sim.regulator import closing_profile
from bendsense.sim.truth import TruthWriter, truth_columns
from bendsense.wire.frames import Decoder, FrameType, Sample, Text, encode_command, encode_setpoint

RATE = 1000.0
TAU = 0.025


@pytest.fixture(scope="module")
def board():
    # coarse tables (2 kPa) keep the build short; the physics is tested in test_sim_grasp.py
    return GraspBoard(gripper_config(3), default_objects(3), rate_hz=RATE, seed=0, regulation=Regulation(tau_s=TAU),
                      step_pa=2000.0)


def _truth_rows(path):
    with open(path, encoding="utf-8") as fh:
        assert fh.readline().startswith("# bendsense")
        return list(csv.DictReader(fh))


class _Port:
    """The host side of a simulated board: raw bytes in and out, frames decoded."""

    def __init__(self, dev):
        self.fd = os.open(dev.port, os.O_RDWR | os.O_NOCTTY)
        self.decoder = Decoder()

    def send(self, data):
        os.write(self.fd, data)

    def read(self, seconds):
        frames, end = [], time.monotonic() + seconds
        while time.monotonic() < end:
            if select.select([self.fd], [], [], 0.02)[0]:
                frames += self.decoder.feed(os.read(self.fd, 65536))
        return frames

    def close(self):
        os.close(self.fd)


def test_gripper_board_streams_v2_and_answers_setpoints(board, tmp_path):
    board.reset()
    truth = TruthWriter(tmp_path / "truth.csv", truth_columns(board.truth_fingers, board.n_lines))
    # this host holds line 1 for 0.25 s without a frame: no watchdog here (tests/control/test_watchdog.py has it)
    with SimulatedDevice(board, rate_hz=RATE, n_channels=board.n_channels, truth=truth, watchdog_ms=0) as dev:
        port = _Port(dev)
        port.send(encode_command(FrameType.START))
        frames = port.read(0.15)
        port.send(encode_setpoint(1, 60_000))
        port.send(encode_setpoint(7, 10_000))  # no such line: a TEXT line, nothing changes
        frames += port.read(0.25)
        port.send(encode_command(FrameType.STOP))
        frames += port.read(0.05)
        rows = _truth_rows(tmp_path / "truth.csv")  # readable while the board runs
        stats = dev.stats
        port.close()
    truth.close()
    samples = [f for f in frames if isinstance(f, Sample)]
    texts = [f.text for f in frames if isinstance(f, Text)]
    assert len(samples) > 300 and stats.setpoints == 1
    assert any("SETPOINT line 7" in t and "no such pressure line" in t for t in texts)
    by_seq = {int(r["seq"]): r for r in rows}
    for s in samples:
        assert len(s.adc) == 48 and len(s.pressures_pa) == 3 and s.pressure_pa == s.pressures_pa[0]
        row = by_seq[s.seq]
        assert int(row["t_us"]) == s.t_us
        for k in range(3):
            assert s.pressures_pa[k] == round(float(row[f"line{k}_pressure_pa"]))
    # line 1 is the host's from the SETPOINT on; its pressure follows the first-order lag exactly
    seqs = sorted(by_seq)  # TEXT frames take sequence numbers too: frames are counted by row
    first = next(i for i, q in enumerate(seqs) if float(by_seq[q]["line1_setpoint_pa"]) == 60_000)
    assert all(float(by_seq[q]["line1_setpoint_pa"]) == 60_000 for q in seqs[first:])
    p0 = float(by_seq[seqs[first - 1]]["line1_pressure_pa"])
    p = np.array([float(by_seq[q]["line1_pressure_pa"]) for q in seqs[first:first + 200]])
    n = np.arange(1, p.size + 1)
    assert p == pytest.approx(60e3 + (p0 - 60e3) * np.exp(-n / (RATE * TAU)), rel=1e-9, abs=1e-6)
    # lines 0 and 2 still follow the closing profile (a ramp from 0: below the touch, no force)
    t = np.array([int(by_seq[q]["t_us"]) for q in seqs]) / 1e6
    for line in (0, 2):
        setpoints = np.array([float(by_seq[q][f"line{line}_setpoint_pa"]) for q in seqs])
        assert setpoints == pytest.approx(closing_profile(t, close_pa=DEFAULT_CLOSE_PA), abs=1e-6)
    assert max(float(by_seq[q]["line0_pressure_pa"]) for q in seqs) < DEFAULT_TOUCH_PRESSURE_PA[0]
    assert all(float(by_seq[q]["thumb_fx_n"]) == 0.0 for q in seqs)
    touching = [q for q in seqs if float(by_seq[q]["line1_pressure_pa"]) > DEFAULT_TOUCH_PRESSURE_PA[1] + 1e3]
    assert touching and all(float(by_seq[q]["index_fx_n"]) < 0 < float(by_seq[q]["index_fy_n"]) for q in touching)
    assert {by_seq[q]["middle_contact_s_m"] for q in seqs} == {"0.095"}


def test_single_actuator_board_sends_version_1_without_prefixes(tmp_path):
    config = load_config()
    board = GraspBoard(config, default_objects(1, 20.0, 0.1, 30e3), rate_hz=RATE, step_pa=4000.0)
    assert board.truth_fingers is None and board.n_channels == 16 and board.n_lines == 1
    truth = TruthWriter(tmp_path / "t.csv", truth_columns())
    # this host holds line 0 for 0.3 s without a frame: no watchdog here (tests/control/test_watchdog.py has it)
    with SimulatedDevice(board, rate_hz=RATE, n_channels=16, truth=truth, autostart=True, watchdog_ms=0) as dev:
        port = _Port(dev)
        port.send(encode_setpoint(0, 50_000))
        samples = [f for f in port.read(0.3) if isinstance(f, Sample)]
        port.close()
    truth.close()
    rows = _truth_rows(tmp_path / "t.csv")
    assert list(rows[0]) == ["seq", "t_us", "fx_n", "fy_n", "contact_s_m", "setpoint_pa", "pressure_pa"]
    assert samples and all(s.pressures_pa == () and len(s.adc) == 16 for s in samples)
    assert float(rows[-1]["setpoint_pa"]) == 50_000 and math.hypot(float(rows[-1]["fx_n"]), float(rows[-1]["fy_n"])) > 0


def test_a_scenario_board_answers_setpoint_with_a_text_line():
    with SimulatedDevice(ramp_source(4), rate_hz=200.0, n_channels=4, autostart=True) as dev:
        port = _Port(dev)
        port.send(encode_setpoint(0, 20_000))
        frames = port.read(0.2)
        port.close()
        assert dev.stats.setpoints == 0
    assert any(isinstance(f, Text) and "ignored" in f.text for f in frames)
    assert all(f.pressure_pa == 20_000 for f in frames if isinstance(f, Sample))


@pytest.mark.parametrize(
    "args, hint, words",
    [
        (["--object-stiffness", "3"], "--object-stiffness", "--fingers K or --object"),
        (["--object", "rigid", "--object-stiffness", "3"], "--object-stiffness", "compliant only"),
        (["--fingers", "2", "--object-s-m", "0.2"], "--object-s-m", "(0, L = 0.134 m]"),
        (["--fingers", "2", "--object-s-m", "0.1,0.1,0.1"], "--object-s-m", "one per finger (2), got 3"),
        (["--fingers", "2", "--object-touch-kpa", "130"], "--object-touch-kpa", "limit 120 kPa"),
        (["--fingers", "2", "--channels", "32"], "--channels", "16 channels"),
        (["--fingers", "5"], "--fingers", "1<=x<=4"),
        (["--source", "ramp", "--truth", "x.csv"], "--truth", "not ramp"),
        (["--object", "rigid", "--contact-s-m", "0.1"], "--contact-s-m", "--object-s-m"),
        (["--replay", ".", "--fingers", "2"], "--fingers", "played back, not simulated"),
        (["--replay", ".", "--truth", "t.csv"], "--truth", "played back, not simulated"),
    ],
)
def test_sim_device_grasp_options_are_checked(args, hint, words):
    res = CliRunner().invoke(main, ["sim-device", "--seconds", "0.1", *args])
    assert res.exit_code == 2, res.output
    assert hint in res.output and words in res.output and "Traceback" not in res.output


def test_sim_device_refuses_an_existing_truth_file(tmp_path):
    target = tmp_path / "truth.csv"
    target.write_text("mine\n")
    res = CliRunner().invoke(main, ["sim-device", "--seconds", "0.1", "--truth", str(target)])
    assert res.exit_code != 0 and "exists" in res.output and target.read_text() == "mine\n"


def test_sim_device_fingers_truth_is_readable_after_a_kill(tmp_path):
    target = tmp_path / "truth.csv"
    proc = subprocess.Popen(
        [sys.executable, "-c", "from bendsense.cli import main; main()", "sim-device", "--fingers", "2",
         "--autostart", "--rate", "1000", "--truth", str(target)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
    )
    with proc:
        port = proc.stdout.readline().strip()
        fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
        decoder, samples, end = Decoder(), [], time.monotonic() + 0.5
        while time.monotonic() < end:
            if select.select([fd], [], [], 0.02)[0]:
                samples += [f for f in decoder.feed(os.read(fd, 65536)) if isinstance(f, Sample)]
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        os.close(fd)
    rows = _truth_rows(target)
    assert list(rows[0])[:5] == ["seq", "t_us", "thumb_fx_n", "thumb_fy_n", "thumb_contact_s_m"]
    assert list(rows[0])[-2:] == ["line1_setpoint_pa", "line1_pressure_pa"]
    complete = [r for r in rows if None not in r.values() and r["line1_pressure_pa"]]
    assert [int(r["seq"]) for r in complete] == list(range(len(complete)))
    assert len(complete) >= len(samples) - 1 > 200 and all(len(s.pressures_pa) == 2 for s in samples)


def test_simulate_gripper_writes_config_calibration_and_a_board_session(board, tmp_path):
    from bendsense import load_config as load
    from bendsense.calibration import Calibration
    from bendsense.session import read_session
    from bendsense.session.fingers import split_session
    from bendsense.sim.actuator import SimulatedActuator

    out = tmp_path / "grip"
    res = CliRunner().invoke(main, ["simulate", "gripper", "-o", str(out), "--fingers", "2", "--seconds", "3",
                                    "--rate", "50"])
    assert res.exit_code == 0, res.output
    gripper = load(out / "gripper.yaml")
    assert gripper.names == ("thumb", "index") and gripper == gripper_config(2)
    session = read_session(out / "session.csv")
    assert session.signals.shape == (150, 32) and session.pressure_pa.shape == (150, 2)
    # the pressures follow the closing profile through the regulators: 0 -> 70 kPa over 2 s, then held
    assert session.pressure_pa[0].tolist() == [0.0, 0.0] and session.pressure_pa[-1] == pytest.approx(70e3, rel=1e-3)
    # the truth is the object's equilibrium at each row's pressure (exact solve; the session's table has 0.5 kPa)
    exact = board.fingers["thumb"].solve(session.pressure_pa[::10, 0])
    truth = np.stack([session.extra["thumb_fx_n"][::10], session.extra["thumb_fy_n"][::10]], axis=-1)
    assert np.abs(truth - exact.force_n).max() < 1e-4 and np.abs(truth).max() > 0.1
    assert set(session.extra["index_contact_s_m"]) == {0.11}
    # the calibration is the simulated sensor's: its offset is the flat sensor's signal
    cal = Calibration.load(out / "calibration.yaml")
    flat = SimulatedActuator.from_config(load_config(), seed=0).sensor.signal(np.zeros(16))
    assert np.abs(np.asarray(cal.offset) - flat).max() < 1.0
    parts = split_session(session, gripper)
    assert list(parts["index"].extra)[-3:] == ["fx_n", "fy_n", "contact_s_m"]


@pytest.mark.parametrize(
    "args, hint",
    [
        (["calibration", "--fingers", "2"], "--fingers"),
        (["time-varying", "--object", "rigid"], "--object"),
        (["gripper", "--frames", "3"], "--frames"),
        (["gripper", "--object-s-m", "0.1,0.2,0.3,0.1"], "--object-s-m"),
    ],
)
def test_simulate_gripper_options_are_checked(tmp_path, args, hint):
    res = CliRunner().invoke(main, ["simulate", *args, "-o", str(tmp_path / "x")])
    assert res.exit_code == 2 and hint in res.output and "Traceback" not in res.output, res.output
    assert not (tmp_path / "x").exists()


def test_sim_device_truth_of_the_single_actuator_scenario(tmp_path):
    from bendsense.sim.scenarios import time_varying_frames

    target = tmp_path / "truth.csv"
    res = CliRunner().invoke(main, ["sim-device", "--seconds", "0.5", "--rate", "100", "--autostart",
                                    "--truth", str(target)])
    assert res.exit_code == 0, res.output
    rows = _truth_rows(target)
    assert list(rows[0]) == ["seq", "t_us", "fx_n", "fy_n", "contact_s_m", "setpoint_pa", "pressure_pa"]
    assert len(rows) >= 5 and [int(r["seq"]) for r in rows] == list(range(len(rows)))  # (a loaded machine: fewer)
    # frame k is the time-varying scenario's frame k (seed 0): its truth, its pressure as set-point
    expected = time_varying_frames(rate_hz=100.0, seed=0, truth=True, duration_s=len(rows) / 100.0)
    for row, (pressure, _, truth) in zip(rows, expected, strict=True):
        assert float(row["fx_n"]) == truth["fx_n"] and float(row["fy_n"]) == truth["fy_n"]
        assert float(row["setpoint_pa"]) == float(row["pressure_pa"]) == pressure
        assert int(row["t_us"]) == round(int(row["seq"]) * 1e6 / 100.0)


def test_gripper_config_maps_fingers_to_channels_and_lines():
    import bendsense.sim
    from bendsense.errors import ConfigError

    gripper = bendsense.sim.gripper_config(4)
    assert gripper.names == ("thumb", "index", "middle", "ring")
    assert gripper.n_channels == 64 and gripper.n_lines == 4
    for i, finger in enumerate(gripper.fingers):
        assert finger.channels == tuple(range(16 * i + 1, 16 * i + 17)) and finger.pressure_line == i
        assert finger.config.sensor == load_config().sensor
    for bad in (0, 5, 2.0, True):
        with pytest.raises(ConfigError, match="fingers: must be an integer in 1..4"):
            bendsense.sim.gripper_config(bad)


@pytest.mark.parametrize(("args", "option"), [
    (["simulate", "gripper", "--seconds", "1e6"], "--seconds"), (["simulate", "gripper", "--rate", "1e7"], "--rate"),
    (["demo", "--seconds", "1e7"], "--seconds")])
def test_a_session_beyond_the_memory_is_refused_before_any_work(tmp_path, args, option):
    """Held whole in memory, 1e6 s of a gripper (900 GB) would grow until the machine kills it: one line naming the
    option, the memory it needs and the longest session that fits; nothing written."""
    start = time.perf_counter()
    res = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "out")])
    assert res.exit_code == 1 and len(res.output.strip().splitlines()) == 1, res.output
    assert re.fullmatch(rf"Error: {option}: (gripper of 3 fingers|demo) would hold [\d,]+ frames in memory, about "
                        r"[\d.]+ [GT]B; this machine has [\d.]+ [GMT]B available \(at most [\d,]+ s at [\d.e+]+ Hz\)",
                        res.output.strip()), res.output
    assert not (tmp_path / "out").exists() and time.perf_counter() - start < 5.0
