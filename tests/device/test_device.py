"""Driver, simulated board and recorder, end to end over real pseudo-terminals."""

import contextlib
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
from bendsense.device import Driver, Recorder, SimulatedDevice, ramp_source
from bendsense.device import ports as ports_mod
from bendsense.device.driver import Reconnect
from bendsense.device.simdevice import Faults, Firmware
from bendsense.errors import DeviceError, OutputExistsError
from bendsense.session.native import SessionWriter, record_dtype
from bendsense.wire.frames import encode_hello, encode_sample, encode_text

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")

N_CH = 16


def expected_counts(k, n=N_CH, bits=12):
    """The ramp source, written out independently: channel c of frame k is (k + 100 c) mod 2**bits."""
    return tuple((k + 100 * c) % 2**bits for c in range(n))


def wait_for(predicate, timeout=10.0):
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError("timed out")
        time.sleep(0.01)


def drain(drv, until, timeout=15.0):
    out = []
    end = time.monotonic() + timeout
    while not until():
        assert time.monotonic() < end, "timed out"
        out += drv.get_batch(timeout=0.05)
    time.sleep(0.1)
    out += drv.get_batch(timeout=0.1)
    return out


def test_end_to_end_exact_counts():
    """1,000 frames at 500 Hz with injected faults: received + lost == sent, errors == corrupted + truncated."""
    with (
        SimulatedDevice(
            ramp_source(N_CH), rate_hz=500, max_frames=1000,
            faults=Faults(drop=0.03, corrupt=0.03, truncate=0.03, seed=11),
        ) as sim,
        Driver(sim.port) as drv,
    ):
        assert drv.hello.n_channels == N_CH and drv.hello.adc_bits == 12 and drv.hello.rate_hz == 500
        t0 = time.monotonic()
        drv.start()
        wait_for(sim.finished.is_set)
        elapsed = time.monotonic() - t0
        sim.send_text("done")  # ends a truncated last frame, and the TEXT counts in the sequence
        wait_for(lambda: any(e.kind == "text" for e in drv.events))
        got = drain(drv, lambda: True)
    st, ds = sim.stats, drv.stats
    assert st.generated == 1000 and st.tx_overflow == 0
    assert st.dropped > 0 and st.corrupted > 0 and st.truncated > 0
    assert len(got) == st.sent == ds.samples
    assert ds.lost == st.dropped + st.corrupted + st.truncated
    assert len(got) + ds.lost == st.generated
    assert ds.crc_errors + ds.malformed == st.corrupted + st.truncated
    # content: the HELLO had seq 0, so frame k has seq k + 1; counts and device clock follow k
    ks = [r.sample.seq - 1 for r in got]
    assert ks == sorted(set(ks)) and 0 <= ks[0] and ks[-1] <= 999
    assert all(r.sample.adc == expected_counts(k) for r, k in zip(got, ks, strict=True))
    assert all(r.device_us == round(k * 1e6 / 500) for r, k in zip(got, ks, strict=True))
    assert all(r.sample.pressure_pa == 20000 for r in got)
    assert 1.5 < elapsed < 4.0  # paced at 500 Hz, not as fast as possible
    host = np.array([r.host_ns for r in got])
    assert np.all(np.diff(host) >= 0)


def test_clock_and_sequence_wrap_recorded(tmp_path):
    """Device clock (u32 us) and seq wrap mid-recording; the session is continuous."""
    start_t = 2**32 - 100_000  # wraps after 0.1 s
    with (
        SimulatedDevice(
            ramp_source(4), n_channels=4, rate_hz=2000, max_frames=600,
            firmware=Firmware(start_seq=65400, start_t_us=start_t),
        ) as sim,
        Driver(sim.port) as drv,
    ):
        rec = Recorder(drv, tmp_path / "s")
        drv.start()
        rec.start()
        wait_for(sim.finished.is_set)
        wait_for(lambda: rec.stats.records == 600)
        rec.stop()
    s = read_session(tmp_path / "s")
    assert len(s) == 600 and s.n_channels == 4
    np.testing.assert_allclose(s.t_s, np.arange(600) / 2000, atol=1e-9)
    np.testing.assert_array_equal(s.seq, 65401 + np.arange(600))
    np.testing.assert_array_equal(s.signals, [expected_counts(k, 4) for k in range(600)])
    assert s.meta["device"]["n_channels"] == 4 and s.meta["stats"]["lost"] == 0
    assert s.meta["outcome"] == "stopped" and s.meta["torn_bytes"] == 0
    events = (tmp_path / "s" / "events.log").read_text()
    assert "hello: HELLO" in events


def test_disconnect_raises_device_error_and_session_stays_readable(tmp_path):
    with SimulatedDevice(ramp_source(N_CH), rate_hz=1000, faults=Faults(disconnect_after=300)) as sim:
        drv = Driver(sim.port, reconnect=Reconnect(attempts=2, backoff_s=0.02))
        with drv:
            rec = Recorder(drv, tmp_path / "s")
            drv.start()
            t0 = time.monotonic()
            with pytest.raises(DeviceError, match="disconnected.*2 reconnect attempt"):
                rec.run(duration_s=20)
            assert time.monotonic() - t0 < 5
            with pytest.raises(DeviceError, match="disconnected"):
                drv.get(timeout=1)
            with pytest.raises(DeviceError, match="disconnected"):
                next(iter(drv))
        assert sim.stats.disconnected
    s = read_session(tmp_path / "s")
    assert len(s) == sim.stats.sent == 300
    np.testing.assert_array_equal(s.signals[-1], expected_counts(299))
    assert s.meta["outcome"].startswith("device error")
    events = (tmp_path / "s" / "events.log").read_text()
    assert "disconnect: read failed" in events and "reconnect attempt 2/2 failed" in events


@pytest.mark.parametrize("here", [False, True], ids=["reader thread", "reading here"])
def test_reconnect_to_a_port_that_comes_back(tmp_path, here):
    """The port vanishes and reappears (a symlink, as udev would make): the driver reconnects,
    resends HELLO_REQUEST and START, and the sequence gap over the outage is counted. Read in
    the caller's thread (reading_here), the read error hands the port to the reader thread,
    which does the same, and the caller gets the new board's frames."""
    link = tmp_path / "ttyBENDSENSE"
    sim1 = SimulatedDevice(ramp_source(2), n_channels=2, rate_hz=500).start()
    os.symlink(sim1.port, link)
    with Driver(str(link), reconnect=Reconnect(attempts=30, backoff_s=0.05)) as drv, \
            (drv.reading_here() if here else contextlib.nullcontext()):
        drv.start()
        first = drain(drv, lambda: drv.stats.samples >= 50)
        sim1.disconnect()
        # the board comes back, its sequence having moved on by 1000 frames
        with SimulatedDevice(ramp_source(2), n_channels=2, rate_hz=500, firmware=Firmware(start_seq=5000)) as sim2:
            os.unlink(link)
            os.symlink(sim2.port, link)
            second = drain(drv, lambda: drv.stats.samples >= len(first) + 50)
            assert sim2.streaming  # START was resent
    assert drv.stats.reconnects == 1
    kinds = [e.kind for e in drv.events]
    assert "disconnect" in kinds and "reconnect" in kinds
    assert second[-1].sample.seq > 5000
    assert drv.stats.lost == (second[-1].sample.seq - first[0].sample.seq + 1) - len(first) - len(second) - 1


RECORD_SCRIPT = "from bendsense.cli import main; main()"


def test_sigkill_leaves_a_readable_session(tmp_path):
    """A recorder killed with SIGKILL loses at most the last second of frames."""
    rate = 500
    with SimulatedDevice(ramp_source(N_CH), rate_hz=rate) as sim:
        out = tmp_path / "s"
        with open(tmp_path / "stderr.txt", "wb") as err:
            proc = subprocess.Popen(
                [sys.executable, "-c", RECORD_SCRIPT, "-q", "record", sim.port, "-o", str(out), "--quiet-status"],
                stdout=subprocess.DEVNULL,
                stderr=err,
            )
        try:
            wait_for(lambda: (out / "frames.bin").exists() and (out / "frames.bin").stat().st_size > 0, 30)
            time.sleep(1.2)
            generated = sim.stats.generated
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        assert proc.returncode == -signal.SIGKILL
    s = read_session(out)
    assert "end_time_utc" not in s.meta  # it really was killed
    assert len(s) >= generated - rate * 1.0
    k = s.seq - 1
    np.testing.assert_array_equal(np.diff(k), 1)
    np.testing.assert_array_equal(s.signals, [expected_counts(int(i)) for i in k])


def test_reading_here_keeps_every_frame_in_order_and_reads_in_the_callers_thread():
    """Frames queued by the reader thread before, read by the caller within, and after the context: one sequence,
    none lost, none twice; within it the caller's read takes what arrived while it was busy in one read."""
    with SimulatedDevice(ramp_source(N_CH), rate_hz=1000, max_frames=1500,
                         faults=Faults(drop=0.02, corrupt=0.02, seed=5)) as sim, Driver(sim.port) as drv:
        drv.start()
        wait_for(lambda: drv.queued >= 100)  # the reader thread's, taken inside the context first
        got, stamps = [], []
        drv.here_stall_s = 60.0  # the reader thread never reads for this caller, however slow the machine
        with drv.reading_here():
            while len(got) < 600:
                got += drv.get_batch(timeout=0.5, max_items=7)
            time.sleep(0.03)  # busy elsewhere: the reader thread is paused, nothing reads meanwhile
            block = drv.get_batch(timeout=0.5)
            stamps = {r.host_ns for r in block}
            got += block
            got += drv.get_batch(timeout=0.5, max_items=1)  # leaves frames of its read for the queue after
        wait_for(sim.finished.is_set)
        wait_for(lambda: drv.stats.samples == sim.stats.sent)
        while drv.queued:
            got += drv.get_batch(timeout=0.1)
    assert len(block) >= 10 and len(stamps) == 1  # ~30 frames arrived in the 30 ms: one read took them all
    st, ds = sim.stats, drv.stats
    seqs = [r.sample.seq for r in got]
    assert seqs == sorted(set(seqs))
    assert len(got) == st.sent == ds.samples and ds.lost == st.dropped + st.corrupted
    assert all(r.sample.adc == expected_counts(r.sample.seq - 1) for r in got)


def test_a_caller_away_longer_than_here_stall_s_loses_no_frame():
    """A gripper's board (48 channels at 1 kHz) and a caller away for 2 s inside reading_here: the port would fill
    (the board then drops what it cannot write); the reader thread reads for the caller meanwhile, in order."""
    with SimulatedDevice(ramp_source(48), n_channels=48, rate_hz=1000) as sim, Driver(sim.port) as drv, \
            drv.reading_here():
        drv.start()
        got = []
        while len(got) < 200:
            got += drv.get_batch(timeout=0.5)
        time.sleep(2.0)
        assert drv.queued >= 1000  # read by the thread while the caller was away
        while len(got) < 2800:
            got += drv.get_batch(timeout=0.5)
    assert sim.stats.tx_overflow == 0 and drv.stats.lost == 0
    seqs = [r.sample.seq for r in got]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))


def test_reading_here_ends_the_wait_with_the_drivers_error_when_the_board_is_gone():
    """A read error inside the context hands the port to the reader thread (test_reconnect_to_a_port_that_comes_back
    with it); a board that does not come back ends the caller's wait with the driver's error, every frame before it
    taken."""
    with SimulatedDevice(ramp_source(N_CH), rate_hz=1000, faults=Faults(disconnect_after=200)) as sim, \
            Driver(sim.port, reconnect=Reconnect(attempts=2, backoff_s=0.02)) as drv, drv.reading_here():
        drv.start()
        got = []
        with pytest.raises(DeviceError, match="disconnected.*2 reconnect attempt"):
            while True:
                got += drv.get_batch(timeout=1)
        assert [r.sample.seq for r in got] == list(range(1, 201))


@pytest.mark.parametrize("here", [False, True], ids=["reader thread", "reading here"])
def test_a_ctrl_c_at_any_line_of_get_batch_leaves_the_driver_working(here):
    """KeyboardInterrupt raised at each Python line (and return) of a get_batch call in turn, as a Ctrl-C can:
    the next get_batch still returns readings, in order (queue.Queue, interrupted inside its Condition's
    __enter__, kept its lock taken: the next get waited for ever, the control loop's zeros unconfirmed)."""
    with SimulatedDevice(ramp_source(2), n_channels=2, rate_hz=1000) as sim, Driver(sim.port) as drv, \
            (drv.reading_here() if here else contextlib.nullcontext()):
        drv.start()
        seqs, interrupted = [], 0
        for k in range(1, 400):
            events = 0

            def tracer(frame, event, arg, k=k):
                nonlocal events
                if event in ("line", "return"):
                    events += 1
                    if events == k:
                        raise KeyboardInterrupt
                return tracer

            time.sleep(0.002)
            sys.settrace(tracer)
            try:
                seqs += [r.sample.seq for r in drv.get_batch(timeout=0.5)]
            except KeyboardInterrupt:
                interrupted += 1
            finally:
                sys.settrace(None)
            after = []
            check = threading.Thread(target=lambda out=after: out.extend(drv.get_batch(timeout=0.5)), daemon=True)
            check.start()
            check.join(5)
            assert not check.is_alive(), f"get_batch hung after a KeyboardInterrupt at its line event {k}"
            assert after
            seqs += [r.sample.seq for r in after]
            if events < k:
                break  # a call with fewer events than k: every line was interrupted once
    assert interrupted >= 5
    assert seqs == sorted(set(seqs))


def test_loop_url_and_line_dialect():
    with Driver("loop://", handshake=False) as drv:
        drv.write(encode_hello(0, 0, 3, 10, 100, 3300, "loop") + encode_text(1, 5, "hi"))
        drv.write(b"".join(encode_sample(s, 10 * s, [s, 2, 3], pressure_pa=None) for s in (2, 3, 5)))
        drv.start()  # the echoed START command is ignored by the reader
        got = [drv.get(timeout=2) for _ in range(3)]
        assert [r.sample.seq for r in got] == [2, 3, 5]
        assert got[0].sample.pressure_pa is None
        assert drv.hello.firmware == "loop" and drv.n_channels == 3
        assert drv.stats.lost == 1 and drv.stats.frames == 6  # HELLO, TEXT, 3 SAMPLEs, our START echoed
        assert drv.latest().sample.seq == 5
        assert drv.get(timeout=0.05) is None
        assert any(e.kind == "text" and "hi" in e.text for e in drv.events)
    with Driver("loop://", dialect="line", columns=("seq", "ch1", "ch2")) as drv:
        drv.write(b"# comment\n0,1,2\n1 3 4\nbad line\n3,5,6\n")
        got = [drv.get(timeout=2) for _ in range(3)]
        assert [r.sample.adc for r in got] == [(1, 2), (3, 4), (5, 6)]
        assert drv.stats.malformed == 1 and drv.stats.lost == 1


def test_full_queue_counts_drops_and_never_hides_them():
    with Driver("loop://", handshake=False, queue_size=10, queue_block_s=0.01) as drv:
        drv.write(b"".join(encode_sample(s, 0, [s]) for s in range(50)))
        wait_for(lambda: drv.stats.samples == 50)
        assert drv.stats.queue_drops == 40
        assert [r.sample.seq for r in drv.get_batch(timeout=1)] == list(range(10))
        assert drv.latest().sample.seq == 49
        assert any(e.kind == "queue_drop" for e in drv.events)


def test_open_errors():
    with pytest.raises(DeviceError, match="no HELLO within 0.2 s"):
        Driver("loop://", hello_timeout_s=0.2).open()
    with pytest.raises(DeviceError, match="cannot open serial port"):
        Driver("/dev/does-not-exist-bendsense").open()
    with pytest.raises(DeviceError, match="dialect"):
        Driver("loop://", dialect="ascii")
    drv = Driver("loop://", handshake=False).open()
    drv.close()
    with pytest.raises(DeviceError, match="device closed"):
        drv.get(timeout=0.1)
    assert list(drv) == []  # iteration simply ends after close()


def test_sim_device_stops_on_stop_and_counts_commands():
    with SimulatedDevice(ramp_source(1), n_channels=1, rate_hz=1000) as sim, Driver(sim.port) as drv:
        assert not sim.streaming
        drv.start()
        wait_for(lambda: drv.stats.samples > 20)
        drv.stop()
        wait_for(lambda: not sim.streaming)
        n = sim.stats.generated
        time.sleep(0.1)
        assert sim.stats.generated == n
        assert sim.stats.commands == 3 and sim.stats.hellos == 1
    with pytest.raises(DeviceError, match="drop"):
        Faults(drop=1.5)


def test_default_source_gives_pressure_and_counts_per_frame():
    from bendsense.device.simdevice import default_source

    pressure, counts = next(iter(default_source(n_channels=2)))  # the virtual sensor
    assert len(counts) == 2
    assert np.isfinite(pressure) and all(0 <= c < 2**12 for c in counts)


def test_default_source_computes_its_first_frame_before_the_board_streams(monkeypatch):
    """The slow first simulation (numba compiling on a fresh install) happens before the port is
    printed, not while a receiver waits; the frames are those of the scenario, none lost."""
    from itertools import islice

    import bendsense.sim.scenarios as scenarios
    from bendsense.device.simdevice import default_source

    computed = []
    original = scenarios.time_varying_frames

    def watched(*args, **kwargs):
        for frame in original(*args, **kwargs):
            computed.append(frame)
            yield frame

    monkeypatch.setattr(scenarios, "time_varying_frames", watched)
    source = default_source(rate_hz=100.0, seed=1)
    assert len(computed) == 1  # before anyone asked for a frame
    got = list(islice(source, 5))
    expected = list(islice(original(None, 100.0, 1), 5))
    for (p, counts), (p_exp, counts_exp) in zip(got, expected, strict=True):
        assert p == p_exp and np.array_equal(counts, counts_exp)


def test_recorder_refuses_existing_session(tmp_path):
    SessionWriter(tmp_path / "s", record_dtype(1)).close()
    with Driver("loop://", handshake=False) as drv, pytest.raises(OutputExistsError, match="exists and is not empty"):
        Recorder(drv, tmp_path / "s")


@pytest.mark.parametrize("written", [1.0, 0.5])
def test_a_ctrl_c_between_a_write_and_its_count_keeps_the_session_whole(tmp_path, monkeypatch, written):
    """The signal lands after ``os.write`` returned (whole records uncounted) or within it (a torn record): the
    finished session counts what frames.bin holds, whole records only, and reads."""
    import bendsense.session.native as native

    real_write = os.write

    def interrupted(fd, data):
        real_write(fd, bytes(data)[:int(len(data) * written)])
        raise KeyboardInterrupt

    with SessionWriter(tmp_path / "s", record_dtype(2)) as w:
        rec = w.empty(6)
        rec["seq"] = np.arange(6)
        w.write(rec[:4])
        monkeypatch.setattr(native.os, "write", interrupted)
        with pytest.raises(KeyboardInterrupt):
            w.write(rec[4:])
        monkeypatch.undo()
    session = read_session(tmp_path / "s")
    assert len(session) == (6 if written == 1.0 else 5)
    assert (tmp_path / "s" / "frames.bin").stat().st_size == len(session) * rec.dtype.itemsize


# ----------------------------------------------------------------- CLI


def test_cli_devices(monkeypatch):
    monkeypatch.setattr(ports_mod, "list_ports", lambda: [])
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 0 and "no serial ports found" in res.output
    fake = [ports_mod.PortInfo("/dev/ttyACM0", "STM32 Virtual ComPort", "0483:5740", "2061377E5748", "STM")]
    monkeypatch.setattr(ports_mod, "list_ports", lambda: fake)
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 0
    header, row = res.output.splitlines()
    assert header.split() == ["DEVICE", "VID:PID", "SERIAL", "DESCRIPTION"]
    assert row.split()[:3] == ["/dev/ttyACM0", "0483:5740", "2061377E5748"]


def test_cli_record(tmp_path):
    with SimulatedDevice(ramp_source(N_CH), rate_hz=500) as sim:
        res = CliRunner().invoke(main, ["record", sim.port, "-o", str(tmp_path / "s"), "--seconds", "0.5"])
        assert res.exit_code == 0, res.output
        n = len(read_session(tmp_path / "s"))
        assert 100 < n <= 260
        res = CliRunner().invoke(main, ["record", sim.port, "-o", str(tmp_path / "s"), "--seconds", "0.2"])
        assert res.exit_code == 1 and "use --overwrite" in res.output
        res = CliRunner().invoke(
            main, ["record", sim.port, "-o", str(tmp_path / "s"), "--seconds", "0.2", "--overwrite"]
        )
        assert res.exit_code == 0 and len(read_session(tmp_path / "s")) < n
        assert "done: " in res.output
        res = CliRunner().invoke(main, ["-q", "record", sim.port, "-o", str(tmp_path / "q"), "--seconds", "0.2"])
        assert res.exit_code == 0 and res.output == "" and len(read_session(tmp_path / "q")) > 0  # -q: errors only
    res = CliRunner().invoke(main, ["record", "/dev/does-not-exist-bendsense", "-o", str(tmp_path / "t")])
    assert res.exit_code == 1 and "cannot open serial port" in res.output
    assert "Traceback" not in res.output



def test_a_second_record_on_a_port_in_use_is_refused_and_the_first_keeps_every_frame(tmp_path):
    """Two readers of one port take half of each other's bytes: the first recording lost frames and the second
    failed half-way, leaving its session unfinished. The port is opened exclusively: the second is one line, writes
    nothing, and the first loses nothing."""
    with SimulatedDevice(ramp_source(N_CH), rate_hz=500) as sim:
        first = {}
        thread = threading.Thread(target=lambda: first.update(res=CliRunner().invoke(
            main, ["record", sim.port, "-o", str(tmp_path / "a"), "--seconds", "1.5"])))
        thread.start()
        deadline = time.monotonic() + 10
        while not (tmp_path / "a" / "frames.bin").exists() or sim.stats.sent < 50:
            assert time.monotonic() < deadline, "the first recording never started"
            time.sleep(0.02)
        res = CliRunner().invoke(main, ["record", sim.port, "-o", str(tmp_path / "b"), "--seconds", "0.5"])
        thread.join()
    assert res.exit_code == 1, res.output
    assert res.output.strip() == (f"Error: {sim.port}: in use by another program that reads it (another bendsense "
                                  "record, live or control?); one program at a time reads a board")
    assert not (tmp_path / "b").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["a"]
    assert first["res"].exit_code == 0, first["res"].output
    session = read_session(tmp_path / "a")
    assert session.meta["stats"]["lost"] == 0 and session.meta["stats"]["malformed"] == 0
    assert np.all(np.diff(session.seq) == 1) and len(session) > 0.9 * 1.5 * 500

def test_cli_sim_device():
    res = CliRunner().invoke(main, ["sim-device", "--source", "ramp", "--seconds", "0.2", "--rate", "100"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines()[0].startswith("/dev/")
    res = CliRunner().invoke(main, ["sim-device", "--channels", "65"])
    assert res.exit_code == 2 and "expected 1..64" in res.output


def test_recorder_background_thread_with_concurrent_reader(tmp_path):
    """The live view reads latest() while the recorder drains the queue; both see the same stream."""
    with SimulatedDevice(ramp_source(N_CH), rate_hz=1000, max_frames=400) as sim, Driver(sim.port) as drv:
        seen = []
        stop = threading.Event()

        def live():
            while not stop.is_set():
                r = drv.latest()
                if r is not None:
                    seen.append(r.sample.seq)
                time.sleep(0.005)

        t = threading.Thread(target=live)
        t.start()
        with Recorder(drv, tmp_path / "s") as rec:
            drv.start()
            rec.start()
            wait_for(sim.finished.is_set)
            wait_for(lambda: rec.stats.records == 400)
        stop.set()
        t.join()
    s = read_session(tmp_path / "s")
    assert len(s) == 400 and seen and max(seen) == 400


def test_recorder_stopped_while_its_thread_was_starting(tmp_path):
    """Ctrl-C inside ``Thread.start()`` leaves a thread that starts a moment later: leaving the recorder waits for
    it and ends it (it used to raise "cannot join thread before it is started": a traceback instead of one line)."""
    with SimulatedDevice(ramp_source(N_CH), rate_hz=1000, max_frames=100) as sim, Driver(sim.port) as drv:
        rec = Recorder(drv, tmp_path / "s")
        rec._thread = thread = threading.Thread(target=lambda: rec.run(None), daemon=True)
        threading.Timer(0.05, thread.start).start()  # what the interrupted start() left: a thread not yet started
        with rec:
            pass
        assert thread.ident is not None and not thread.is_alive()  # it started, saw the stop, and ended
    assert len(read_session(tmp_path / "s")) <= 100  # a whole, readable session


def test_a_board_whose_hello_lies_about_its_channels_is_one_line_and_counted(tmp_path, caplog):
    """HELLO announces 8 channels, the SAMPLEs carry 16: one line at record time naming both counts, the last line
    counts the skipped and malformed frames as the board's own counters have them, and 'load' is one line."""
    import logging

    with SimulatedDevice(ramp_source(N_CH), n_channels=8, rate_hz=1000, max_frames=200,
                         faults=Faults(truncate=0.1, seed=4)) as sim:
        with caplog.at_level(logging.WARNING, logger="bendsense"):
            res = CliRunner().invoke(main, ["record", sim.port, "-o", str(tmp_path / "s"), "--seconds", "0.6",
                                            "--quiet-status"])
        assert res.exit_code == 0, res.output
        sent, truncated = sim.stats.sent, sim.stats.truncated
    said = [r.getMessage() for r in caplog.records if "HELLO" in r.getMessage()]
    assert said == [f"{sim.port}: the board's HELLO announces 8 channels, but its samples carry 16: they are "
                    "skipped, not recorded (count in the summary)"]
    assert not any("no sample frames arrived" in r.getMessage() for r in caplog.records)
    assert sent == 200 - truncated and 0 < truncated < sent
    assert res.output.strip().splitlines()[-1] == (
        f"done: 0 frames written to {tmp_path / 's'}; {sent} skipped (another channel count or pressure lines than "
        f"the session's); {truncated} malformed; {truncated} lost (0 dropped by the firmware)")
    res = CliRunner().invoke(main, ["load", str(tmp_path / "s"), "export", str(tmp_path / "s.csv")])
    assert res.exit_code == 1 and res.output.strip().splitlines() == [
        f"Error: {tmp_path / 's'}: no frames (an empty recording): {sent} samples were skipped at record "
        "time (another channel count or pressure lines than meta.yaml's; see events.log)"]
