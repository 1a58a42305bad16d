"""Native session directory: layout (DESIGN.md section 3), torn records, CSV export/import."""

import datetime as dt
import logging
import os
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

from bendsense import read_session, read_session_csv
from bendsense.errors import OutputExistsError, SessionError
from bendsense.session import Session, write_session_csv
from bendsense.session.native import (
    SessionWriter,
    dtype_from_list,
    dtype_to_list,
    export_session_csv,
    import_session_csv,
    read_records,
    read_session_dir,
    record_dtype,
)

NO_P = 0x7FFFFFFF


def hand_made_v1(path, rows, n=3):
    """A version-1 session written byte by byte from the format description, not by the writer."""
    path.mkdir()
    meta = {
        "format": "bendsense-session",
        "version": 1,
        "start_time_utc": "2024-05-01T12:00:00.000000Z",
        "n_channels": n,
        "adc_bits": 12,
        "record_dtype": [
            ["host_ns", "<i8"],
            ["t_us", "<u8"],
            ["seq", "<u2"],
            ["status", "|u1"],
            ["pressure_pa", "<i4"],
            ["adc", f"({n},)<u2"],
        ],
        "device": {"firmware": "hand", "n_channels": n, "adc_bits": 12, "rate_hz": 500, "vref_mv": 3300},
    }
    (path / "meta.yaml").write_text(yaml.safe_dump(meta))
    data = b"".join(struct.pack(f"<qQHBi{n}H", *r[:5], *r[5]) for r in rows)
    (path / "frames.bin").write_bytes(data)
    (path / "events.log").write_text("")
    return data


ROWS = [
    # host_ns, t_us (unwrapped, past 2**32), seq (wrapping), status, pressure, adc
    (1_000_000_000, 2**32 - 2000, 65534, 0, 20000, (1, 2, 3)),
    (1_002_000_000, 2**32, 65535, 1, NO_P, (4, 5, 6)),
    (1_004_000_000, 2**32 + 2000, 0, 0, -5, (7, 8, 4095)),
    (1_010_000_000, 2**32 + 8000, 3, 8, 20001, (10, 11, 12)),  # two frames lost in between
]


def test_reads_hand_made_v1_session(tmp_path):
    hand_made_v1(tmp_path / "s", ROWS)
    s = read_session(tmp_path / "s")
    assert isinstance(s, Session) and len(s) == 4 and s.n_channels == 3
    np.testing.assert_allclose(s.t_s, [0.0, 0.002, 0.004, 0.010], atol=1e-12)
    np.testing.assert_array_equal(s.seq, [65534, 65535, 65536, 65539])
    np.testing.assert_array_equal(s.pressure_pa, [20000.0, np.nan, -5.0, 20001.0])
    np.testing.assert_array_equal(s.signals, [[1, 2, 3], [4, 5, 6], [7, 8, 4095], [10, 11, 12]])
    np.testing.assert_allclose(s.extra["host_s"], [0.0, 0.002, 0.004, 0.010], atol=1e-12)
    np.testing.assert_array_equal(s.extra["status"], [0, 1, 0, 8])
    assert s.meta["torn_bytes"] == 0 and s.meta["device"]["firmware"] == "hand"
    assert s.source.endswith("s")


def test_torn_last_record_is_ignored_and_reported(tmp_path, caplog):
    data = hand_made_v1(tmp_path / "s", ROWS)
    with open(tmp_path / "s" / "frames.bin", "ab") as fh:
        fh.write(data[:23])  # a record cut short by a crash
    with caplog.at_level(logging.WARNING, logger="bendsense.session"):
        s = read_session_dir(tmp_path / "s")
    assert len(s) == 4 and s.meta["torn_bytes"] == 23
    assert "torn last record (23 of 29 bytes)" in caplog.text


TX_DROPS = (65535, 65535, 1, 3)  # the firmware's cumulative counter, wrapping: 4 drops in all


def test_writer_layout_matches_the_format(tmp_path):
    dtype = record_dtype(3)
    assert dtype.itemsize == 8 + 8 + 2 + 1 + 2 + 4 + 2 * 3
    assert [dtype.fields[k][1] for k in dtype.names] == [0, 8, 16, 18, 19, 21, 25]
    assert dtype_to_list(dtype) == [
        ["host_ns", "<i8"],
        ["t_us", "<u8"],
        ["seq", "<u2"],
        ["status", "|u1"],
        ["tx_drops", "<u2"],
        ["pressure_pa", "<i4"],
        ["adc", "(3,)<u2"],
    ]
    assert dtype_from_list(dtype_to_list(dtype)) == dtype
    with SessionWriter(tmp_path / "w", record_dtype(3), adc_bits=12, device={"firmware": "x"}, config={"a": 1}) as w:
        assert yaml.safe_load((tmp_path / "w" / "meta.yaml").read_text())["finished"] is False
        rec = w.empty(len(ROWS))
        for i, (r, tx) in enumerate(zip(ROWS, TX_DROPS)):
            rec[i] = (*r[:4], tx, r[4], r[5])
        w.write(rec[:2])
        w.write(rec[2:])
        w.event("gap: 2 frame(s) lost\nbefore seq 3")
    expected = b"".join(struct.pack("<qQHBHi3H", *r[:4], tx, r[4], *r[5]) for r, tx in zip(ROWS, TX_DROPS))
    assert (tmp_path / "w" / "frames.bin").read_bytes() == expected
    meta = yaml.safe_load((tmp_path / "w" / "meta.yaml").read_text())
    assert meta["format"] == "bendsense-session" and meta["version"] == 2 and meta["finished"] is True
    assert meta["n_channels"] == 3 and meta["adc_bits"] == 12 and meta["n_records"] == 4
    s = read_session_dir(tmp_path / "w")
    assert s.meta["tx_drops"] == 4 and s.meta["frames_lost"] == 2 and s.meta["finished"]
    np.testing.assert_array_equal(s.extra["tx_drops"], TX_DROPS)
    assert meta["config"] == {"a": 1} and meta["device"] == {"firmware": "x"}
    dt.datetime.strptime(meta["start_time_utc"], "%Y-%m-%dT%H:%M:%S.%fZ")
    (line,) = (tmp_path / "w" / "events.log").read_text().splitlines()
    stamp, text = line.split(" ", 1)
    dt.datetime.strptime(stamp, "%Y-%m-%dT%H:%M:%S.%fZ")
    assert text == "gap: 2 frame(s) lost before seq 3"


def test_existing_session_is_not_overwritten(tmp_path):
    SessionWriter(tmp_path / "s", record_dtype(2)).close()
    with pytest.raises(OutputExistsError, match="exists and is not empty"):
        SessionWriter(tmp_path / "s", record_dtype(2))
    with SessionWriter(tmp_path / "s", record_dtype(2), overwrite=True) as w:
        w.write(w.empty(3))
    assert len(read_session_dir(tmp_path / "s")) == 3
    with SessionWriter(tmp_path / "t", record_dtype(2)) as w, \
            pytest.raises(SessionError, match="records: expected dtype"):
        w.write(np.zeros(2, dtype=record_dtype(3)))


def test_the_writer_takes_a_record_dtype_only(tmp_path):
    """The layout is record_dtype's, extra columns and lines included; anything else is refused before any output."""
    laid_out = record_dtype(3, "<f8", [("temp_c", "<f4")], 2)
    with SessionWriter(tmp_path / "s", laid_out) as w:
        assert (w.n_channels, w.n_lines, w.dtype) == (3, 2, laid_out)
    shuffled = np.dtype([(name, laid_out.fields[name][0]) for name in reversed(laid_out.names)])
    for bad in (np.dtype([("a", "<i4")]), shuffled, 3, "<u2"):
        with pytest.raises(SessionError, match=r"dtype: expected a record dtype \(record_dtype"):
            SessionWriter(tmp_path / "t", bad)
    assert not (tmp_path / "t").exists()


def test_bad_meta_is_reported(tmp_path):
    hand_made_v1(tmp_path / "s", ROWS)
    meta = yaml.safe_load((tmp_path / "s" / "meta.yaml").read_text())
    (tmp_path / "s" / "meta.yaml").write_text(yaml.safe_dump({**meta, "version": 3}))
    with pytest.raises(SessionError, match="version: expected 1 or 2, got 3"):
        read_session_dir(tmp_path / "s")
    (tmp_path / "s" / "meta.yaml").write_text(yaml.safe_dump({**meta, "format": "other"}))
    with pytest.raises(SessionError, match="format: expected 'bendsense-session', got 'other'"):
        read_session_dir(tmp_path / "s")
    (tmp_path / "s" / "meta.yaml").write_text(yaml.safe_dump({**meta, "record_dtype": [["adc", "<u2"]]}))
    with pytest.raises(SessionError, match="missing fields"):
        read_session_dir(tmp_path / "s")
    (tmp_path / "s" / "meta.yaml").unlink()
    with pytest.raises(SessionError, match="no meta.yaml"):
        read_records(tmp_path / "s")


def test_empty_session_reads(tmp_path):
    SessionWriter(tmp_path / "s", record_dtype(4)).close()
    s = read_session_dir(tmp_path / "s")
    assert len(s) == 0 and s.signals.shape == (0, 4)


def test_export_to_csv_and_back(tmp_path):
    hand_made_v1(tmp_path / "s", ROWS)
    export_session_csv(tmp_path / "s", tmp_path / "s.csv")
    with pytest.raises(OutputExistsError, match="exists"):
        export_session_csv(tmp_path / "s", tmp_path / "s.csv")
    native, csv = read_session(tmp_path / "s"), read_session_csv(tmp_path / "s.csv")
    np.testing.assert_array_equal(csv.t_s, native.t_s)
    np.testing.assert_array_equal(csv.signals, native.signals)
    np.testing.assert_array_equal(csv.pressure_pa, native.pressure_pa)
    np.testing.assert_array_equal(csv.seq, native.seq)
    np.testing.assert_array_equal(csv.extra["status"], native.extra["status"])
    # and import the CSV into a second native session
    import_session_csv(tmp_path / "s.csv", tmp_path / "s2")
    again = read_session_dir(tmp_path / "s2")
    np.testing.assert_allclose(again.t_s, native.t_s, atol=1e-12)
    np.testing.assert_array_equal(again.signals, native.signals)
    np.testing.assert_array_equal(again.pressure_pa, native.pressure_pa)
    np.testing.assert_array_equal(again.seq, native.seq)
    np.testing.assert_array_equal(again.extra["status"], native.extra["status"])
    assert read_records(tmp_path / "s2")[0].dtype == record_dtype(3)


def test_import_float_signals_and_extra_columns(tmp_path):
    t = 5.0 + np.arange(6) * 0.01
    rng = np.random.default_rng(1)
    sig = rng.normal(size=(6, 2))
    fx = rng.normal(size=6)
    s = Session(t, sig, np.full(6, 12_500.0), extra={"fx_n": fx, "label": np.array(list("abcdef"), dtype=object)})
    write_session_csv(s, tmp_path / "in.csv")
    import_session_csv(tmp_path / "in.csv", tmp_path / "s")
    back = read_session_dir(tmp_path / "s")
    np.testing.assert_allclose(back.t_s, t, atol=1e-6)  # whole microseconds, offset kept
    np.testing.assert_array_equal(back.signals, sig)  # stored as <f8, exact
    np.testing.assert_array_equal(back.pressure_pa, 12_500.0)
    np.testing.assert_array_equal(back.extra["fx_n"], fx)
    assert "label" not in back.extra
    np.testing.assert_array_equal(back.seq, np.arange(6))


def test_import_of_a_text_status_column_keeps_the_frames_and_says_so(tmp_path, caplog):
    # e.g. a results.csv's status ("ok", "not_converged"): no device status bits
    t = np.arange(3) * 0.01
    s = Session(t, np.ones((3, 2)), np.full(3, 1e4), extra={"status": np.array(["ok", "no_force", "ok"], dtype=object)})
    write_session_csv(s, tmp_path / "in.csv")
    with caplog.at_level(logging.WARNING, logger="bendsense"):
        import_session_csv(tmp_path / "in.csv", tmp_path / "s")
    back = read_session_dir(tmp_path / "s")
    assert len(back) == 3 and back.extra["status"].tolist() == [0, 0, 0]
    assert "text column 'status' is not stored" in caplog.text


def test_saved_version_1_session_still_loads():
    s = read_session(Path(__file__).parents[1] / "data" / "sessions" / "v1_finished")
    assert len(s) == 5 and s.meta["version"] == 1 and s.meta["finished"] and s.meta["tx_drops"] == 0
    np.testing.assert_array_equal(s.seq, [65534, 65535, 65536, 65537, 65538])
    np.testing.assert_array_equal(s.signals[:, 2], [4095, 4094, 4093, 4092, 4091])
    np.testing.assert_array_equal(s.pressure_pa, [20000, 21000, 22000, 23000, 24000])


def test_killed_recording_is_read_and_flagged_unfinished(tmp_path, caplog):
    w = SessionWriter(tmp_path / "s", record_dtype(3), adc_bits=12)
    rec = w.empty(6)
    rec["seq"] = np.arange(6)
    w.write(rec)
    with open(tmp_path / "s" / "frames.bin", "ab") as fh:
        fh.write(b"\x01" * 7)  # the recorder was killed in the middle of a write
    # killed: the files are closed by the OS, meta.yaml is never rewritten (finished: false)
    os.close(w._fd)
    w._events.close()
    with caplog.at_level(logging.WARNING, logger="bendsense.session"):
        s = read_session_dir(tmp_path / "s")
    assert len(s) == 6 and not s.meta["finished"] and s.meta["torn_bytes"] == 7
    assert "unfinished recording (no clean stop: killed, crashed or still recording); 6 records present; " \
           f"a torn last record (7 of {w.dtype.itemsize} bytes) ignored" in caplog.text


def test_an_unfinished_recording_larger_than_memory_is_one_line(tmp_path):
    """A killed recording's frames.bin has no n_records to hold its size to: 4 TiB (a sparse file) is refused."""
    w = SessionWriter(tmp_path / "s", record_dtype(3), adc_bits=12)
    w.write(w.empty(6))
    os.close(w._fd)
    w._events.close()
    os.truncate(tmp_path / "s" / "frames.bin", 4 * 2**40)
    with pytest.raises(SessionError, match=r"frames.bin: [\d,]+ records of \d+ bytes \(4096.0 GiB\) do not fit in "
                                           r"this machine's memory"):
        read_session_dir(tmp_path / "s")


def test_finished_session_reports_lost_records_with_the_numbers(tmp_path):
    with SessionWriter(tmp_path / "s", record_dtype(2)) as w:
        w.write(w.empty(1500))
    frames = tmp_path / "s" / "frames.bin"
    frames.write_bytes(frames.read_bytes()[: 745 * w.dtype.itemsize])
    with pytest.raises(SessionError, match=r"frames.bin: 745 of 1,500 records present; 755 lost"):
        read_session_dir(tmp_path / "s")


def test_pressures_below_1_kpa_are_read_as_a_session_at_rest(tmp_path):
    # a board at rest (or a firmware sending kPa: estimate_force warns, judged against the config)
    rows = [(1_000_000_000 + i, 1000 * i, i, 0, 50 + i, (1, 2, 3)) for i in range(5)]
    hand_made_v1(tmp_path / "kpa", rows)
    assert read_session(tmp_path / "kpa").pressure_pa.tolist() == [50, 51, 52, 53, 54]





def test_a_new_sample_field_reaches_every_layer(tmp_path, monkeypatch):
    """The recipe of bendsense.wire.frames.SAMPLE_FIELDS, step 1: one table entry, and the record
    dtype, the recorder's copy, the Session, the CSV export and the import all carry the field."""
    from types import SimpleNamespace

    import bendsense.device.recorder as recorder
    import bendsense.session.native as native
    from bendsense.wire.frames import SAMPLE_FIELDS, SampleField

    old = tmp_path / "v2"
    with SessionWriter(old, record_dtype(2)) as w:  # written before the field existed
        w.write(native.sample_records(w.dtype, [SimpleNamespace(seq=0, status=0, tx_drops=0, pressure_pa=None,
                                                                adc=(1, 2))], [0], [0]))
    temp = SampleField("temp_cdeg", "<i2", 3, "board temperature [0.01 °C]")
    monkeypatch.setattr(native, "SAMPLE_FIELDS", (*SAMPLE_FIELDS, temp))
    monkeypatch.setattr(native, "FORMAT_VERSION", 3)
    monkeypatch.setattr(native, "READ_VERSIONS", (1, 2, 3))
    assert recorder.sample_records is native.sample_records  # what the recorder copies a sample with

    dtype = record_dtype(2)
    assert dtype.names == ("host_ns", "t_us", "seq", "status", "tx_drops", "pressure_pa", "temp_cdeg", "adc")
    samples = [SimpleNamespace(seq=k, status=0, tx_drops=0, pressure_pa=20_000.4, adc=(k, 2 * k), temp_cdeg=2150 - k)
               for k in range(5)]
    path = tmp_path / "v3"
    with SessionWriter(path, record_dtype(2)) as w:
        w.write(native.sample_records(w.dtype, samples, range(0, 5000, 1000), range(0, 50, 10)))
    s = read_session(path)
    assert s.meta["version"] == 3
    np.testing.assert_array_equal(s.extra["temp_cdeg"], [2150, 2149, 2148, 2147, 2146])
    np.testing.assert_array_equal(s.pressure_pa, 20_000.0)

    export_session_csv(path, tmp_path / "v3.csv")
    np.testing.assert_array_equal(read_session_csv(tmp_path / "v3.csv").extra["temp_cdeg"], s.extra["temp_cdeg"])
    import_session_csv(tmp_path / "v3.csv", tmp_path / "back")
    records, _ = read_records(tmp_path / "back")
    assert records.dtype.names == dtype.names  # back into its own field, not an extra column
    np.testing.assert_array_equal(records["temp_cdeg"], [2150, 2149, 2148, 2147, 2146])

    assert "temp_cdeg" not in read_session(old).extra  # older sessions still read
    with pytest.raises(SessionError, match=r"missing fields \['temp_cdeg'\]"):
        dtype_from_list(dtype_to_list(record_dtype(2)[[n for n in dtype.names if n != "temp_cdeg"]]), version=3)


def test_a_folder_holding_one_session_csv_names_it(tmp_path):
    (tmp_path / "tv").mkdir()
    (tmp_path / "tv" / "session.csv").write_text("t_s,ch1\n0,1\n")
    with pytest.raises(SessionError, match=r"tv: not a session directory \(no meta\.yaml\); it holds session\.csv: "
                                           r"give .*tv/session\.csv$"):
        read_session(tmp_path / "tv")
