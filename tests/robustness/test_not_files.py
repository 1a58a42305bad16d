"""Inputs that are not files: a FIFO, a device or a socket where a file belongs is refused at once.

Real FIFOs (``os.mkfifo``) with no writer: opening one for reading blocks until a
writer comes, so a reader that does not check first hangs. Every test runs under an
alarm that turns a hang into a failure. Also the bounds of what the machine cannot
do: ``simulate --frames`` beyond the free memory and ``sim-device --rate`` beyond what
the link carries.
"""

import os
import re
import signal
import socket

import pytest
from click.testing import CliRunner

import bendsense
from bendsense.calibration import Calibration
from bendsense.cli import main
from bendsense.errors import ArgumentError, ConfigError, DeviceError, SessionError
from robustness.test_invalid_corpus import GOOD_CAL, GOOD_CSV


class Hung(Exception):
    pass


@pytest.fixture(autouse=True)
def no_hang():
    def alarm(signum, frame):
        raise Hung("a reader blocked on a FIFO")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(20)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


@pytest.fixture
def fifo(tmp_path):
    path = tmp_path / "pipe.csv"
    os.mkfifo(path)
    return path


def _session_dir(tmp_path):
    from bendsense.session.native import SessionWriter, record_dtype

    d = tmp_path / "rec"
    with SessionWriter(d, record_dtype(16), adc_bits=12) as w:
        rec = w.empty(3)
        rec["t_us"] = [0, 2000, 4000]
        rec["seq"] = [0, 1, 2]
        rec["adc"] = 2000
        w.write(rec)
    return d


FIFO = "a FIFO \\(named pipe\\), not a"


@pytest.mark.parametrize("reader, error", [
    (bendsense.read_session, SessionError),
    (bendsense.read_session_csv, SessionError),
    (bendsense.load_config, ConfigError),
    (Calibration.load, ConfigError),
    (Calibration.fit, ConfigError),
])
def test_a_fifo_is_refused_by_every_reader(fifo, reader, error):
    with pytest.raises(error, match=re.escape(str(fifo)) + ": " + FIFO):
        reader(fifo)


@pytest.mark.parametrize("reader", [bendsense.read_session, bendsense.read_session_csv])
def test_dev_zero_is_a_character_device(reader):
    with pytest.raises(SessionError, match=r"^/dev/zero: a character device, not a session"):
        reader("/dev/zero")


def test_a_socket_is_refused(tmp_path):
    path = tmp_path / "s.csv"
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(path))
        with pytest.raises(SessionError, match="a socket, not a session"):
            bendsense.read_session(path)


def test_a_directory_where_a_file_belongs(tmp_path):
    with pytest.raises(ConfigError, match="a directory, not a config"):
        bendsense.load_config(tmp_path)


def test_a_session_directory_whose_frames_are_a_fifo(tmp_path):
    d = _session_dir(tmp_path)
    (d / "frames.bin").unlink()
    os.mkfifo(d / "frames.bin")
    with pytest.raises(SessionError, match=r"frames\.bin: a FIFO \(named pipe\), not a frames\.bin of a session"):
        bendsense.read_session(d)


def test_a_session_directory_whose_meta_is_a_fifo(tmp_path):
    d = _session_dir(tmp_path)
    (d / "meta.yaml").unlink()
    os.mkfifo(d / "meta.yaml")
    with pytest.raises(SessionError, match=r"meta\.yaml: a FIFO"):
        bendsense.read_session(d)


def test_a_manifest_naming_a_fifo_recording(tmp_path):
    os.mkfifo(tmp_path / "flat.csv")
    (tmp_path / "m.yaml").write_text("flat: flat.csv\nstrips:\n  - {radius_m: 0.04, recording: flat.csv}\n")
    with pytest.raises(ConfigError, match=r"flat: recording 'flat\.csv' is a FIFO \(named pipe\), not a session CSV"):
        Calibration.fit(tmp_path / "m.yaml")


def test_results_whose_shape_is_a_fifo(tmp_path):
    from bendsense.results import read_results, write_results
    from bendsense.shape.pcc import reconstruct

    session = bendsense.read_session_csv(GOOD_CSV)
    shape = reconstruct(session.signals, Calibration.load(GOOD_CAL), bendsense.load_config().sensor)
    write_results(tmp_path / "out", session, shape)
    (tmp_path / "out" / "shape.npz").unlink()
    os.mkfifo(tmp_path / "out" / "shape.npz")
    with pytest.raises(SessionError, match=r"shape\.npz: a FIFO"):
        read_results(tmp_path / "out")


def test_batch_discovery_refuses_a_fifo_before_any_work(tmp_path):
    from bendsense.batch import discover_sessions

    (tmp_path / "a.csv").write_text(GOOD_CSV.read_text())
    os.mkfifo(tmp_path / "b.csv")
    with pytest.raises(SessionError, match=r"b\.csv: a FIFO"):
        discover_sessions(tmp_path)


def test_replay_of_a_fifo_is_refused(fifo):
    from bendsense.device.replay import ReplayDevice

    with pytest.raises(SessionError, match=FIFO):
        ReplayDevice(fifo)


def _cli(tmp_path, args):
    os.chdir(tmp_path)
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code != 0, result.output
    assert isinstance(result.exception, SystemExit), repr(result.exception)
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.output
    return lines[0]


@pytest.mark.parametrize("args", [
    ["load", "{fifo}", "--calibration", GOOD_CAL, "reconstruct", "save", "out"],
    ["load", GOOD_CSV, "--calibration", "{fifo}", "reconstruct", "save", "out"],
    ["load", GOOD_CSV, "--config", "{fifo}", "--calibration", GOOD_CAL, "reconstruct", "save", "out"],
    ["calibrate", "{fifo}", "-o", "cal.yaml"],
    ["process", "{fifo}", "--calibration", GOOD_CAL, "-o", "out"],
    ["identify", "free-bending", "{fifo}", "-o", "cfg.yaml"],
    ["sim-device", "--replay", "{fifo}"],
])
def test_cli_refuses_a_fifo_in_one_line(tmp_path, fifo, args, monkeypatch):
    monkeypatch.chdir(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    line = _cli(work, [str(a).replace("{fifo}", str(fifo)) for a in args])
    assert re.search(re.escape(str(fifo)) + ": " + FIFO, line), line
    assert list(work.iterdir()) == []


# --- what the machine cannot do ---------------------------------------------------------------


def test_simulate_refuses_frames_beyond_the_free_memory(tmp_path, monkeypatch):
    from bendsense.sim import scenarios

    monkeypatch.chdir(tmp_path)
    line = _cli(tmp_path, ["simulate", "tip-loads", "-o", "sim", "--frames", "100000000"])
    assert re.search(r"--frames: tip-loads would hold 4,400,000,000 frames in memory, about 52\.8 TB; this machine "
                     r"has .* available \(at most [\d,]+ frames per configuration\)", line), line
    assert not (tmp_path / "sim").exists()
    line = _cli(tmp_path, ["simulate", "time-varying", "-o", "sim", "--rate", "1e9"])  # a rate: named, and what fits
    assert re.search(r"^Error: --rate: time-varying would hold 10,000,000,000 frames in memory, about 120 TB; .* "
                     r"\(at most [\d,]+ frames: [\d.e+-]+ s at 1e\+09 Hz, or [\d.e+]+ Hz for 10 s\)$", line), line
    assert not (tmp_path / "sim").exists()
    # the bound is the machine's: with 1 GB free, 5,000 frames per configuration (2.9 GB) are too many
    monkeypatch.setattr(scenarios, "available_memory_bytes", lambda: 1e9)
    with pytest.raises(ArgumentError, match=r"frames_per_config: .* \(at most 1,325 frames per configuration\)"):
        scenarios.simulate("tip-loads", tmp_path / "sim2", frames_per_config=5000)
    assert not (tmp_path / "sim2").exists()
    # a rate: the option named, and the rate that fits the time-varying scenario's 10 s
    fits = (1e9 - scenarios.BASE_BYTES) / scenarios.BYTES_PER_FRAME["time-varying"] / 10.0
    with pytest.raises(ArgumentError, match=rf"^rate_hz × duration_s: .* or {re.escape(f'{fits:.3g}')} Hz for 10 s\)$"):
        scenarios.simulate("time-varying", tmp_path / "sim2", rate_hz=fits * 1.01)
    scenarios.check_memory("time-varying", {"rate_hz": fits * 0.99})  # below it: nothing to say


def test_sim_device_refuses_a_rate_the_link_cannot_carry():
    from bendsense.device.simdevice import SimulatedDevice, max_rate_hz

    result = CliRunner().invoke(main, ["sim-device", "--rate", "1e9"])
    assert result.exit_code == 2
    assert "Invalid value for --rate: expected at most 22,943 Hz" in result.output
    # 53 bytes a frame of 16 channels at 1.216 MB/s; fewer channels, shorter frames, faster
    assert max_rate_hz(16) == 22943 and max_rate_hz(1) > max_rate_hz(16) > max_rate_hz(64)
    with pytest.raises(DeviceError, match="rate_hz: expected at most 22,943 Hz"):
        SimulatedDevice(lambda k: (None, [0] * 16), rate_hz=1e6)


def test_replay_refuses_a_recording_faster_than_the_link(tmp_path):
    from bendsense.device.replay import ReplayDevice

    rows = "\n".join(f"{k * 1e-6:.6f},1,2" for k in range(5))  # 1 MHz: t_s in microseconds by mistake?
    (tmp_path / "fast.csv").write_text("t_s,ch1,ch2\n" + rows + "\n")
    with pytest.raises(SessionError, match=r"fast\.csv: frames 1 us apart \(1,000,000 Hz\), more than a USB"):
        ReplayDevice(tmp_path / "fast.csv")


def test_an_output_directory_whose_manifest_is_a_fifo_does_not_block(tmp_path):
    from bendsense import output

    (tmp_path / "out").mkdir()
    os.mkfifo(tmp_path / "out" / output.MANIFEST_NAME)
    assert output.read_manifest(tmp_path / "out") is None  # not a manifest; before, open() waited for a writer
