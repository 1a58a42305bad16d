"""Replay of recorded sessions over a pseudo-terminal (``sim-device --replay``)."""

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from click.testing import CliRunner

from bendsense import read_session
from bendsense.cli import main
from bendsense.device import Driver, Recorder
from bendsense.device.replay import ReplayDevice
from bendsense.errors import SessionError
from bendsense.session import Session, write_session_csv
from bendsense.session.native import NO_PRESSURE, SessionWriter, record_dtype

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")


def make_recording(path, n=300, n_ch=6, seed=3):
    """A native session as a board would leave it: jittered clock, seq gaps and a wrap, status bits,
    frames without pressure."""
    rng = np.random.default_rng(seed)
    w = SessionWriter(path, record_dtype(n_ch), adc_bits=12, device={"firmware": "test-board"})
    rec = w.empty(n)
    dt = rng.integers(900, 1100, n)  # ~1 kHz with jitter [us]
    rec["t_us"] = 5_000_000 + np.cumsum(dt)
    rec["host_ns"] = rec["t_us"].astype(np.int64) * 1000
    steps = np.where(rng.random(n) < 0.05, 3, 1)  # lost frames in the original recording
    rec["seq"] = (65_400 + np.cumsum(steps)) % 65536  # wraps
    rec["status"] = rng.integers(0, 16, n)
    rec["tx_drops"] = (65_530 + np.cumsum(rng.random(n) < 0.03)) % 65536  # the firmware's own losses, wrapping
    p = rng.integers(0, 100_000, n)
    p[rng.random(n) < 0.1] = NO_PRESSURE
    rec["pressure_pa"] = p
    rec["adc"] = rng.integers(0, 4096, (n, n_ch))
    w.write(rec)
    w.close()
    return read_session(path)


def record_replay(dev, out):
    with dev, Driver(dev.port) as drv:
        rec = Recorder(drv, out)
        drv.start()
        rec.start()
        end = time.monotonic() + 20
        while not dev.finished.is_set() or rec.stats.records < dev.stats.sent:
            assert time.monotonic() < end, "timed out"
            time.sleep(0.02)
        rec.stop()
    return read_session(out)


def assert_same_frames(a, b):
    assert len(a) == len(b)
    np.testing.assert_array_equal(a.signals, b.signals)
    np.testing.assert_array_equal(a.pressure_pa, b.pressure_pa)  # NaN where no reading, equal NaN
    np.testing.assert_array_equal(a.seq - a.seq[0], b.seq - b.seq[0])
    np.testing.assert_array_equal(a.extra["status"], b.extra["status"])
    np.testing.assert_array_equal(a.extra["tx_drops"], b.extra["tx_drops"])
    np.testing.assert_allclose(a.t_s - a.t_s[0], b.t_s - b.t_s[0], rtol=0, atol=1e-9)


def test_replayed_session_recorded_again_is_identical(tmp_path):
    original = make_recording(tmp_path / "orig")
    again = record_replay(ReplayDevice(tmp_path / "orig"), tmp_path / "again")
    assert_same_frames(original, again)
    # the original's lost frames show up as the same gaps, and nothing else was lost
    assert again.meta["stats"]["lost"] == int(np.sum(np.diff(original.seq) - 1))
    assert again.meta["device"]["n_channels"] == 6 and again.meta["device"]["adc_bits"] == 12
    assert abs(again.meta["device"]["rate_hz"] - 1000) <= 10  # the median interval of the jittered clock


@pytest.mark.realtime
def test_replay_keeps_the_original_timing(tmp_path):
    original = make_recording(tmp_path / "orig", n=400)
    with ReplayDevice(original) as dev, Driver(dev.port) as drv:
        drv.start()
        readings = []
        end = time.monotonic() + 10
        while len(readings) < 400:
            assert time.monotonic() < end
            readings += drv.get_batch(timeout=0.05)
    host = np.array([r.host_ns for r in readings]) * 1e-9
    span = original.t_s[-1] - original.t_s[0]
    # the host sees the frames over the recording's duration (pacing), not in one burst
    assert span * 0.9 < host[-1] - host[0] < span * 1.2 + 0.05
    lag = (host - host[0]) - (original.t_s - original.t_s[0])
    assert np.percentile(np.abs(lag - np.median(lag)), 90) < 0.02


def test_replay_speed_and_loop(tmp_path):
    original = make_recording(tmp_path / "orig", n=100)
    with ReplayDevice(original, speed=4.0, loop=True) as dev, Driver(dev.port) as drv:
        drv.start()
        readings = []
        t0 = time.monotonic()
        end = t0 + 10
        while len(readings) < 250:
            assert time.monotonic() < end
            readings += drv.get_batch(timeout=0.05)
        elapsed = time.monotonic() - t0
    span = original.t_s[-1] - original.t_s[0]  # 0.1 s per pass at speed 1
    assert elapsed < 2.5 * span * 1.5 / 4 + 0.3
    adc = np.array([r.sample.adc for r in readings[:250]])
    k = np.arange(250) % 100
    np.testing.assert_array_equal(adc, original.signals[k])
    # the clock goes on across passes: strictly increasing device time
    t = np.array([r.device_us for r in readings[:250]])
    assert np.all(np.diff(t) > 0)
    # sequence numbers: the recorded ones, numbered on across passes (no spurious gap between passes)
    span = original.seq[-1] - original.seq[0] + 1
    expected = (original.seq[k] + (np.arange(250) // 100) * span) % 65536
    np.testing.assert_array_equal([r.sample.seq for r in readings[:250]], expected)
    # the firmware's drop counter counts on across passes too
    drops = original.extra["tx_drops"].astype(np.int64)
    expected = (drops[k] + (np.arange(250) // 100) * (drops[-1] - drops[0])) % 65536
    np.testing.assert_array_equal([r.sample.tx_drops for r in readings[:250]], expected)


def test_replay_of_a_session_csv(tmp_path):
    n = 50
    t = 0.25 + np.arange(n) * 0.002
    sig = np.arange(n * 3).reshape(n, 3) % 4096
    write_session_csv(Session(t, sig, np.linspace(0, 5e4, n)), tmp_path / "s.csv")
    again = record_replay(ReplayDevice(tmp_path / "s.csv"), tmp_path / "again")
    original = read_session(tmp_path / "s.csv")
    np.testing.assert_array_equal(again.signals, original.signals)
    np.testing.assert_array_equal(again.pressure_pa, np.round(original.pressure_pa))
    np.testing.assert_allclose(again.t_s, t - t[0], atol=1e-9)
    np.testing.assert_array_equal(np.diff(again.seq), 1)


def test_replay_refuses_signals_that_are_not_counts(tmp_path):
    write_session_csv(Session([0.0, 0.1], [[1.5, 2.0], [1.0, 2.0]], [0.0, 0.0]), tmp_path / "v.csv")
    with pytest.raises(SessionError, match=r"frame 0, ch1: expected ADC counts"):
        ReplayDevice(tmp_path / "v.csv")
    res = CliRunner().invoke(main, ["sim-device", "--replay", str(tmp_path / "v.csv")])
    assert res.exit_code == 1 and "expected ADC counts" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(main, ["sim-device", "--loop"])
    assert res.exit_code == 2 and "--replay" in res.output


@pytest.mark.parametrize("option", [["--rate", "100"], ["--channels", "6"], ["--adc-bits", "10"],
                                    ["--source", "ramp"]])
def test_replay_refuses_the_options_of_the_virtual_board(tmp_path, option):
    """What the recording fixes is not silently ignored: one line naming the option, exit 2."""
    make_recording(tmp_path / "orig", n=20)
    res = CliRunner().invoke(main, ["sim-device", "--replay", str(tmp_path / "orig"), *option, "--seconds", "0.1"])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert res.output.strip().splitlines() == [f"Error: {option[0]} does not apply to --replay: the recording "
                                                "gives it (--speed changes the pace)"]


CLI = [sys.executable, "-c", "from bendsense.cli import main; main()"]


class Lines:
    """The lines a subprocess writes to a pipe, collected on a thread (never blocking the test)."""

    def __init__(self, pipe):
        self.lines = []
        self._thread = threading.Thread(target=lambda: self.lines.extend(iter(pipe.readline, "")), daemon=True)
        self._thread.start()

    def wait_for(self, text, timeout=20.0):
        end = time.monotonic() + timeout
        while not any(text in line for line in self.lines):
            assert time.monotonic() < end, f"no {text!r} in {self.lines}"
            time.sleep(0.02)

    def join(self):
        self._thread.join(10)
        return "".join(self.lines)


def finish(proc):
    """Kill ``proc`` if it still runs, and close its pipes."""
    if proc is None:
        return
    if proc.poll() is None:
        proc.kill()
    proc.communicate()


def replay_process(session):
    proc = subprocess.Popen([*CLI, "sim-device", "--replay", str(session)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    return proc, proc.stdout.readline().strip()


def test_cli_replay_then_record(tmp_path):
    """The commands a user runs: 'sim-device --replay' in one process, 'record --seconds' in another that
    outlasts the replay: record ends normally, sim-device says once that the replay finished and keeps the port
    open until Ctrl-C."""
    original = make_recording(tmp_path / "orig", n=200)
    proc, port = replay_process(tmp_path / "orig")
    try:
        err = Lines(proc.stderr)
        res = CliRunner().invoke(main, ["record", port, "-o", str(tmp_path / "again"), "--seconds", "1.5",
                                        "--quiet-status"])
        assert res.exit_code == 0, res.output
        assert "done: 200 frames written" in res.output and "disconnect" not in res.output
        err.wait_for("replay finished")
        assert proc.poll() is None  # still serving the port, silent
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0
        text = err.join()
        assert text.count("replay finished: 200 frames sent") == 1 and "Traceback" not in text
    finally:
        finish(proc)
    again = read_session(tmp_path / "again")
    assert_same_frames(original, again)
    assert again.meta["finished"] and again.meta["stats"]["reconnects"] == 0
    assert "disconnect" not in (tmp_path / "again" / "events.log").read_text()


@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
def test_record_without_seconds_outlives_the_replay(tmp_path, stop):
    """'record' with no --seconds, stopped by Ctrl-C (or SIGTERM) after the replay ended: exit 130 (143), a finished
    session identical frame by frame to the original (no 'device disconnected', no reconnect attempts)."""
    original = make_recording(tmp_path / "orig", n=300)
    board, port = replay_process(tmp_path / "orig")
    rec = None
    try:
        board_err = Lines(board.stderr)
        rec = subprocess.Popen([*CLI, "record", port, "-o", str(tmp_path / "again"), "--quiet-status"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        board_err.wait_for("replay finished")
        time.sleep(0.5)  # silence after the last frame: not a disconnect
        assert rec.poll() is None
        rec.send_signal(getattr(signal, stop))
        out, err = rec.communicate(timeout=20)
        assert rec.returncode == 128 + getattr(signal, stop), err
        assert err.splitlines()[-1].startswith(f"Interrupted ({stop}): kept 300 frames in ")
        assert "disconnect" not in err and "Traceback" not in err
        board.send_signal(signal.SIGTERM)  # a board stopped with kill: its counts, exit 0
        assert board.wait(10) == 0
        assert "generated 300" in board_err.join()
    finally:
        finish(board)
        finish(rec)
    again = read_session(tmp_path / "again")
    assert_same_frames(original, again)
    assert again.meta["finished"] and again.meta["outcome"] == "interrupted"
    assert "disconnect" not in (tmp_path / "again" / "events.log").read_text()


def test_a_pressure_beyond_the_wire_format_is_refused_before_replay():
    from bendsense.device.replay import replay_frames
    from bendsense.errors import SessionError
    from bendsense.session import Session

    s = Session([0.0, 0.001], [[100.0, 200.0], [101.0, 201.0]], [50e3, 3e9], source="big.csv")
    with pytest.raises(SessionError, match=r"big\.csv: frame 1, pressure_pa: 3e\+09 Pa does not fit"):
        replay_frames(s)
