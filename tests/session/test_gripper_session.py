"""Sessions with several pressure lines (a gripper's board): Session, session CSV, native sessions,
the recorder and the replay (DESIGN.md sections 2b and 3).

Expected bytes and layouts are written out here (struct, hand-written CSV text), not taken
from the code under test.
"""

import os
import struct
import time

import numpy as np
import pytest
import yaml

from bendsense import read_session, read_session_csv
from bendsense.device import Driver, Recorder
from bendsense.device.replay import ReplayDevice, replay_frames
from bendsense.errors import SessionError
from bendsense.session import Session, write_session_csv
from bendsense.session.native import (
    SessionWriter,
    export_session_csv,
    import_session_csv,
    record_dtype,
    sample_records,
)
from bendsense.wire.frames import NO_PRESSURE, Sample, encode_hello, encode_sample

pty_only = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")


def lines_session(n=6, n_ch=3, k=3, source=""):
    t = np.arange(n) * 1e-3
    p = np.column_stack([20_000.0 + 1000 * j + 10.0 * np.arange(n) for j in range(k)])
    p[1, k - 1] = np.nan  # a line without a reading in one frame
    sig = (np.arange(n * n_ch).reshape(n, n_ch) * 7) % 4096
    return Session(t, sig, p, seq=np.arange(n) + 40, extra={"fx_n": np.linspace(0, 0.1, n)}, source=source)


# ----------------------------------------------------------------- Session


def test_session_pressure_shapes():
    s = lines_session()
    assert s.pressure_pa.shape == (6, 3) and s.n_lines == 3
    np.testing.assert_array_equal(s.line_pressure_pa(1), 21_000 + 10.0 * np.arange(6))
    one = Session([0, 1e-3], [[1], [2]], [[5e4], [6e4]])  # one line: (frames,), as every single-line caller wants
    assert one.pressure_pa.shape == (2,) and one.n_lines == 1
    np.testing.assert_array_equal(one.line_pressure_pa(0), [5e4, 6e4])
    assert Session([0, 1e-3], [[1], [2]], 5e4).pressure_pa.shape == (2,)
    # select keeps the lines, also for one frame
    assert s.select(2).pressure_pa.shape == (1, 3)
    np.testing.assert_array_equal(s.select(slice(2, 4)).pressure_pa, s.pressure_pa[2:4])
    np.testing.assert_array_equal(s.select(s.t_s > 3e-3).pressure_pa, s.pressure_pa[4:])
    filled = s.with_pressure(1.0)
    assert filled.pressure_pa[1, 2] == 1.0 and filled.pressure_pa[1, 1] == s.pressure_pa[1, 1]


def test_session_pressure_errors():
    with pytest.raises(SessionError, match=r"pressure_pa: expected one number or shape \(2,\) \(frames of t_s\), got "
                                           r"shape \(3, 2\) \(several pressure lines: \(2, n_lines\)\)"):
        Session([0, 1e-3], [[1], [2]], np.zeros((3, 2)))
    # as many lines as frames: which axis is which is said by meta n_lines (as every reader and Session sets it)
    with pytest.raises(SessionError, match=r"got shape \(2, 2\); a pressure per line with as many lines as frames "
                                           r"needs meta n_lines: 2"):
        Session([0, 1e-3], [[1], [2]], [[1e4, 2e4], [1e4, 2e4]])
    square = Session([0, 1e-3], [[1], [2]], [[1e4, 2e4], [1e4, 2e4]], meta={"n_lines": 2})
    assert square.n_lines == 2
    three = lines_session(n=6, k=3)
    assert three.meta["n_lines"] == 3 and three.select(slice(0, 3)).pressure_pa.shape == (3, 3)
    with pytest.raises(SessionError, match=r"line: 3 is not a pressure line of g\.csv \(it has lines 0\.\.2\)"):
        lines_session(source="g.csv").line_pressure_pa(3)
    with pytest.raises(SessionError, match=r"line: 1 is not a pressure line of the session \(it has line 0\)"):
        Session([0.0], [[1]], [1e4]).line_pressure_pa(1)


# ----------------------------------------------------------------- session CSV


def test_session_csv_with_lines_round_trip(tmp_path):
    s = lines_session()
    write_session_csv(s, tmp_path / "g.csv")
    text = (tmp_path / "g.csv").read_text()
    assert text.splitlines()[1] == "# n_lines: 3"
    rows = [line for line in text.splitlines() if not line.startswith("#")]
    assert rows[0] == "t_s,line0_pressure_pa,line1_pressure_pa,line2_pressure_pa,ch1,ch2,ch3,seq,fx_n"
    assert rows[2].split(",")[3] == "nan"
    back = read_session_csv(tmp_path / "g.csv")
    np.testing.assert_array_equal(back.pressure_pa, s.pressure_pa)  # bit for bit, NaN where no reading
    np.testing.assert_array_equal(back.signals, s.signals)
    np.testing.assert_array_equal(back.extra["fx_n"], s.extra["fx_n"])


def test_session_csv_single_line_is_unchanged(tmp_path):
    s = Session([0.0, 0.001], [[1.0, 2.0], [3.0, 4.0]], [20_000.0, 20_500.0])
    write_session_csv(s, tmp_path / "one.csv")
    assert (tmp_path / "one.csv").read_text() == ("# written by bendsense (a session CSV, docs/formats.md)\n"
                                                  "t_s,pressure_pa,ch1,ch2\n0.0,20000.0,1.0,2.0\n"
                                                  "0.001,20500.0,3.0,4.0\n")


def test_session_csv_reads_kpa_lines_and_empty_cells(tmp_path):
    (tmp_path / "k.csv").write_text("t_s,ch1,line1_pressure_kpa,line0_pressure_pa,truth\n"
                                    "0,5,40.5,20000,a\n0.001,6,,21000,b\n")
    s = read_session_csv(tmp_path / "k.csv")
    np.testing.assert_array_equal(s.pressure_pa, [[20_000, 40_500], [21_000, np.nan]])
    assert list(s.extra) == ["truth"]


@pytest.mark.parametrize(
    "header, match",
    [
        ("t_s,ch1,pressure_pa,line0_pressure_pa", r"line 1: give pressure_pa \(one pressure line\) or "
                                                   r"line<k>_pressure_pa columns \(several\), not both"),
        ("t_s,ch1,line0_pressure_pa,line2_pressure_pa", r"line 1: pressure line columns must be line0..line2; "
                                                         r"missing line1_pressure_pa"),
        ("t_s,ch1,line0_pressure_pa,line1_pressure_pa,line1_pressure_kpa",
         r"line 1: pressure line 1 given twice \(line1_pressure_pa and line1_pressure_kpa\)"),
    ],
)
def test_session_csv_line_column_errors(tmp_path, header, match):
    n = header.count(",")
    (tmp_path / "bad.csv").write_text(header + "\n" + ",".join(["0"] + ["1000"] * n) + "\n")
    with pytest.raises(SessionError, match=match):
        read_session_csv(tmp_path / "bad.csv")


def test_session_csv_line_units_are_checked_by_name(tmp_path):
    (tmp_path / "u.csv").write_text("t_s,ch1,line0_pressure_kpa,line1_pressure_kpa\n0,1,20,45\n0.001,1,20,5e4\n")
    with pytest.raises(SessionError, match=r"line 1, column line1_pressure_kpa: readings up to 50000 kPa "
                       r"\(over 1 MPa\); looks like pascals: name the column line1_pressure_pa"):
        read_session_csv(tmp_path / "u.csv")
    (tmp_path / "inf.csv").write_text("t_s,ch1,line0_pressure_pa,line1_pressure_pa\n0,1,20000,inf\n")
    with pytest.raises(SessionError, match=r"line 2, column line1_pressure_pa: must be finite, got 'inf'"):
        read_session_csv(tmp_path / "inf.csv")


# ----------------------------------------------------------------- native sessions


def test_record_layout_with_lines():
    one = record_dtype(4)
    assert record_dtype(4, n_lines=1) == one and "pressures_pa" not in one.names
    dt = record_dtype(4, n_lines=3)
    assert dt.names == ("host_ns", "t_us", "seq", "status", "tx_drops", "pressure_pa", "adc", "pressures_pa")
    assert dt.itemsize == 8 + 8 + 2 + 1 + 2 + 4 + 2 * 4 + 4 * 3
    for bad in (0, 256, 2.0, True):
        with pytest.raises(SessionError, match=r"n_lines: expected 1..255 pressure lines"):
            record_dtype(4, n_lines=bad)


def test_native_session_stores_every_line_byte_for_byte(tmp_path):
    samples = [Sample(7, 100, 2, 1, 0, 30_000, (11, 12), (30_000, None, 45_000)),
               Sample(8, 200, 2, 0, 0, None, (13, 14), (None, 40_000, 46_000))]
    with SessionWriter(tmp_path / "s", record_dtype(2, n_lines=3), adc_bits=12) as w:
        w.write(sample_records(w.dtype, samples, [5, 6], [100, 200]))
    raw = (tmp_path / "s" / "frames.bin").read_bytes()
    assert raw == (struct.pack("<qQHBHi2H3i", 5, 100, 7, 1, 0, 30_000, 11, 12, 30_000, NO_PRESSURE, 45_000)
                   + struct.pack("<qQHBHi2H3i", 6, 200, 8, 0, 0, NO_PRESSURE, 13, 14, NO_PRESSURE, 40_000, 46_000))
    meta = yaml.safe_load((tmp_path / "s" / "meta.yaml").read_text())
    assert meta["n_lines"] == 3 and ["pressures_pa", "(3,)<i4"] in meta["record_dtype"]
    s = read_session(tmp_path / "s")
    np.testing.assert_array_equal(s.pressure_pa, [[30_000, np.nan, 45_000], [np.nan, 40_000, 46_000]])
    assert "pressures_pa" not in s.extra


def test_one_line_sessions_are_as_before(tmp_path):
    samples = [Sample(1, 10, 1, 0, 0, 20_000, (5,)), Sample(2, 20, 1, 0, 0, 20_000, (6,), (20_000,))]
    with SessionWriter(tmp_path / "one", record_dtype(1)) as w:
        w.write(sample_records(w.dtype, samples, [1, 2], [10, 20]))
    assert (tmp_path / "one" / "frames.bin").read_bytes() == (struct.pack("<qQHBHiH", 1, 10, 1, 0, 0, 20_000, 5)
                                                                + struct.pack("<qQHBHiH", 2, 20, 2, 0, 0, 20_000, 6))
    assert "n_lines" not in yaml.safe_load((tmp_path / "one" / "meta.yaml").read_text())
    assert read_session(tmp_path / "one").pressure_pa.shape == (2,)


def test_sample_records_fills_and_refuses_lines():
    dt = record_dtype(1, n_lines=2)
    rec = sample_records(dt, [Sample(1, 0, 1, 0, 0, 7_000, (1,))], [0], [0])  # a version-1 sample
    assert rec["pressures_pa"].tolist() == [[7_000, NO_PRESSURE]] and rec["pressure_pa"][0] == 7_000
    with pytest.raises(SessionError, match=r"samples: sample 0 has 3 pressure lines, the session 2"):
        sample_records(dt, [Sample(1, 0, 1, 0, 0, 1, (1,), (1, 2, 3))], [0], [0])


def test_import_export_round_trip_with_lines(tmp_path):
    s = lines_session()
    write_session_csv(s, tmp_path / "g.csv")
    import_session_csv(tmp_path / "g.csv", tmp_path / "nat")
    nat = read_session(tmp_path / "nat")
    np.testing.assert_array_equal(nat.pressure_pa, s.pressure_pa)
    np.testing.assert_array_equal(nat.signals, s.signals)
    assert nat.meta["n_lines"] == 3
    export_session_csv(tmp_path / "nat", tmp_path / "back.csv")
    back = read_session_csv(tmp_path / "back.csv")
    np.testing.assert_array_equal(back.pressure_pa, s.pressure_pa)
    np.testing.assert_array_equal(back.extra["fx_n"], s.extra["fx_n"])
    np.testing.assert_array_equal(back.seq, s.seq)


def edit_meta(path, **changes):
    meta = yaml.safe_load((path / "meta.yaml").read_text())
    meta.update(changes)
    (path / "meta.yaml").write_text(yaml.safe_dump(meta, sort_keys=False))


def test_native_reader_refuses_inconsistent_lines(tmp_path):
    write_session_csv(lines_session(), tmp_path / "g.csv")
    import_session_csv(tmp_path / "g.csv", tmp_path / "a")
    edit_meta(tmp_path / "a", n_lines=2)
    with pytest.raises(SessionError, match=r"n_lines is 2, but record_dtype holds 3 pressure line\(s\)"):
        read_session(tmp_path / "a")
    edit_meta(tmp_path / "a", n_lines=3, record_dtype=[[k, "(3,)<f4" if k == "pressures_pa" else v]
                                                      for k, v in yaml.safe_load(
                                                          (tmp_path / "a" / "meta.yaml").read_text())["record_dtype"]])
    with pytest.raises(SessionError, match=r"field pressures_pa: expected \(n_lines,\)<i4 with 2..255 lines"):
        read_session(tmp_path / "a")
    # a record whose pressure_pa disagrees with its line 0: damaged, never read as data
    import_session_csv(tmp_path / "g.csv", tmp_path / "b")
    raw = bytearray((tmp_path / "b" / "frames.bin").read_bytes())
    raw[8 + 8 + 2 + 1 + 2: 8 + 8 + 2 + 1 + 2 + 4] = struct.pack("<i", 1)  # record 0's pressure_pa
    (tmp_path / "b" / "frames.bin").write_bytes(bytes(raw))
    with pytest.raises(SessionError, match=r"record 0: pressure_pa \(1\) differs from line 0 of pressures_pa "
                                           r"\(20000\); the records are damaged"):
        read_session(tmp_path / "b")


def test_set_lines_only_before_the_first_record(tmp_path):
    with SessionWriter(tmp_path / "s", record_dtype(1)) as w:
        w.set_lines(2)
        assert yaml.safe_load((tmp_path / "s" / "meta.yaml").read_text())["n_lines"] == 2
        w.write(sample_records(w.dtype, [Sample(1, 0, 1, 0, 0, 1e4, (1,), (1e4, 2e4))], [0], [0]))
        with pytest.raises(SessionError, match=r"n_lines: the session already holds 1 records of 2 pressure"):
            w.set_lines(3)
    np.testing.assert_array_equal(read_session(tmp_path / "s").pressure_pa, [[1e4, 2e4]])


# ----------------------------------------------------------------- recorder and replay


@pty_only
def test_replay_of_a_gripper_session_sends_v2_and_records_every_line(tmp_path):
    s = lines_session(n=120, n_ch=4, k=3)
    write_session_csv(s, tmp_path / "g.csv")
    frames = replay_frames(s)
    assert frames["pressure_pa"].shape == (120, 3)
    with ReplayDevice(tmp_path / "g.csv") as dev, Driver(dev.port) as drv:
        rec = Recorder(drv, tmp_path / "again")
        drv.start()
        rec.start()
        end = time.monotonic() + 20
        while not dev.finished.is_set() or rec.stats.records < dev.stats.sent:
            assert time.monotonic() < end, "timed out"
            time.sleep(0.02)
        rec.stop()
        assert drv.latest().sample.pressures_pa == (20_000 + 1190, 21_000 + 1190, 22_000 + 1190)
    again = read_session(tmp_path / "again")
    np.testing.assert_array_equal(again.pressure_pa, s.pressure_pa)
    np.testing.assert_array_equal(again.signals, s.signals)
    np.testing.assert_array_equal(again.seq - again.seq[0], s.seq - s.seq[0])
    assert again.meta["n_lines"] == 3


def test_replay_refuses_a_line_beyond_the_wire_format():
    s = Session([0.0, 0.001, 0.002], [[1.0], [2.0], [3.0]], [[5e4, 1e4], [5e4, 3e9], [5e4, 1e4]], source="big.csv")
    with pytest.raises(SessionError, match=r"big\.csv: frame 1, line 1 pressure_pa: 3e\+09 Pa does not fit"):
        replay_frames(s)


def test_recorder_skips_samples_with_other_lines_and_says_so(tmp_path):
    with Driver("loop://", handshake=False) as drv:
        rec = Recorder(drv, tmp_path / "s")
        drv.write(encode_hello(0, 0, 2, 12, 1000, 3300, "x"))
        drv.write(b"".join(encode_sample(k, 1000 * k, [k, k], pressures_pa=[1000 + k, 2000 + k]) for k in range(1, 4)))
        drv.write(encode_sample(4, 4000, [4, 4], pressures_pa=[1, 2, 3]) + encode_sample(5, 5000, [5, 5], 1500))
        drv.write(encode_sample(6, 6000, [6, 6], pressures_pa=[1006, 2006]))
        rec.start()
        end = time.monotonic() + 10
        while rec.stats.records + rec.stats.skipped < 6:
            assert time.monotonic() < end, "timed out"
            time.sleep(0.02)
        stats = rec.stop()
    assert (stats.records, stats.skipped) == (4, 2)
    s = read_session(tmp_path / "s")
    np.testing.assert_array_equal(s.pressure_pa, [[1001, 2001], [1002, 2002], [1003, 2003], [1006, 2006]])
    assert "sample(s) with a number of pressure lines other than 2" in (tmp_path / "s" / "events.log").read_text()


def test_replay_refuses_more_lines_than_a_sample_carries():
    s = Session([0.0], [[1.0]], np.full((1, 256), 1e4), source="wide.csv")
    with pytest.raises(SessionError, match=r"wide\.csv: 256 pressure lines; a SAMPLE carries at most 255"):
        replay_frames(s)


@pty_only
def test_cli_replay_of_a_gripper_session_then_record(tmp_path):
    """The commands a user runs: 'sim-device --replay' of a three-line session CSV, 'record' of its port."""
    import signal
    import subprocess
    import sys

    from click.testing import CliRunner

    from bendsense.cli import main

    s = lines_session(n=80, n_ch=4, k=3)
    write_session_csv(s, tmp_path / "g.csv")
    proc = subprocess.Popen([sys.executable, "-c", "from bendsense.cli import main; main()", "sim-device", "--replay",
                             str(tmp_path / "g.csv")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        res = CliRunner().invoke(main, ["record", port, "-o", str(tmp_path / "again"), "--seconds", "1",
                                        "--quiet-status"])
        assert res.exit_code == 0, res.output
        assert "done: 80 frames written" in res.output
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
        assert proc.returncode == 0 and "Traceback" not in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    again = read_session(tmp_path / "again")
    np.testing.assert_array_equal(again.pressure_pa, s.pressure_pa)
    assert again.meta["n_lines"] == 3
