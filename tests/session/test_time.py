"""Time that does not increase: session CSVs are refused (tests/data/invalid/sessions/t_*.csv),
native sessions keep a device clock reset working, bridged by the host clock, with a warning.
"""

import logging

import numpy as np
import pytest

import bendsense
from bendsense.errors import SessionError
from bendsense.session.native import SessionWriter, record_dtype


def _native(path, t_us, host_ns=None):
    n = len(t_us)
    with SessionWriter(path, record_dtype(4), adc_bits=12) as w:
        rec = w.empty(n)
        rec["t_us"] = t_us
        rec["host_ns"] = np.arange(n) * 2_000_000 if host_ns is None else host_ns
        rec["seq"] = np.arange(n)
        rec["adc"] = 2000
        w.write(rec)
    return path


def test_a_board_reset_is_bridged_by_the_host_clock(tmp_path, caplog):
    # 20 frames at 2 ms, the board resets (clock back to 0), 10 more frames
    t_us = np.r_[np.arange(20) * 2000, np.arange(10) * 2000]
    host = np.arange(30) * 2_000_000 + np.r_[np.zeros(20), np.full(10, 5_000_000)].astype(np.int64)  # 5 ms outage
    path = _native(tmp_path / "reset", t_us, host)
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        s = bendsense.read_session(path)
    assert np.all(np.diff(s.t_s) > 0)
    np.testing.assert_allclose(s.t_s[20] - s.t_s[19], 0.007)  # the host's interval across the reset
    np.testing.assert_allclose(np.diff(s.t_s[20:]), 0.002)  # the device clock's after it
    assert "goes back or stands still at 1 frame(s) (frame 20: 0 us after 38000 us; a board reset?)" in caplog.text
    assert "continues from the host clock (frames 20)" in caplog.text


def test_a_repeated_device_time_read_in_one_burst_takes_the_typical_interval(tmp_path, caplog):
    t_us = np.array([0, 1000, 2000, 2000, 3000, 4000])
    host = np.array([0, 1, 2, 2, 3, 4]) * 1_000_000
    host[3] = host[2]  # both frames read in one burst: no host interval either
    path = _native(tmp_path / "repeat", t_us, host)
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        s = bendsense.read_session(path)
    np.testing.assert_allclose(s.t_s, [0, 0.001, 0.002, 0.003, 0.004, 0.005])
    assert "frame 3: 2000 us after 2000 us" in caplog.text


def test_a_device_clock_past_the_u32_wrap_is_read_without_a_word(tmp_path, caplog):
    # the driver unwraps t_us as it records: frames.bin holds a clock past 2^32 us (71.6 min)
    t_us = 2**32 - 3000 + np.arange(6) * 2000
    path = _native(tmp_path / "wrap", t_us)
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        s = bendsense.read_session(path)
    np.testing.assert_allclose(s.t_s, np.arange(6) * 0.002)
    assert "device clock" not in caplog.text


@pytest.mark.parametrize("times, expect", [
    ([0, 1, 1, 2], r"line 4, column t_s: time repeats \(1 s after 1 s on line 3\)"),
    ([0, 2, 1, 3], r"line 4, column t_s: time runs backwards \(1 s after 2 s on line 3\)"),
    ([3, 2, 1, 0], r"line 3, column t_s: time runs backwards .* 3 rows out of order in all \(also lines 4, 5\)"),
])
def test_csv_time_must_increase(tmp_path, times, expect):
    path = tmp_path / "t.csv"
    path.write_text("t_s,ch1\n" + "".join(f"{t},{k}\n" for k, t in enumerate(times)))
    with pytest.raises(SessionError, match=r"t\.csv: " + expect):
        bendsense.read_session(path)


def test_csv_time_after_a_skipped_blank_line_names_the_right_line(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("t_s,ch1\n0,1\n\n1,2\n0.5,3\n")
    with pytest.raises(SessionError, match=r"line 5, column t_s: time runs backwards \(0\.5 s after 1 s on line 4\)"):
        bendsense.read_session_csv(path)
