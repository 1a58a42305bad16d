"""Frozen files of each format still load: a captured byte stream and a native session.

``tests/data/formats/`` holds one run of the simulated board (``make.py`` there wrote it
and says how): ``stream_v1.bin``, the bytes the driver read (wire protocol version 1),
and ``session_v2/``, the native session (format version 2) the recorder wrote from them.
The tests read the committed files with the public readers and compare them with a
decoder written here from DESIGN.md section 3's byte layout alone (``struct``, numpy,
``binascii.crc_hqx``), so that a change of either format, or of what the readers make
of it, fails here.
"""

from __future__ import annotations

import binascii
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

from bendsense import read_session, read_session_csv
from bendsense.session.native import export_session_csv, read_records, record_dtype
from bendsense.wire.frames import Decoder, Hello, Sample, Text

DATA = Path(__file__).parents[1] / "data" / "formats"
STREAM = DATA / "stream_v1.bin"
SESSION = DATA / "session_v2"

N_CHANNELS = 16
SAMPLES = 289  # of the 300 the board made: 7 dropped, 4 corrupted on the way
NO_PRESSURE = 0x7FFFFFFF

# DESIGN.md section 3, "Recorded session (native)": host_ns, t_us, seq, status, pressure_pa, adc[n],
# packed, little-endian; version 2 adds the SAMPLE's tx_drops after status (bendsense.session.native)
RECORD_V2 = [["host_ns", "<i8"], ["t_us", "<u8"], ["seq", "<u2"], ["status", "|u1"], ["tx_drops", "<u2"],
             ["pressure_pa", "<i4"], ["adc", f"({N_CHANNELS},)<u2"]]


# --------------------------------------------------------------------------- an independent decoder


def cobs_decode(block: bytes) -> bytes | None:
    """COBS, undone: each code byte c is followed by c - 1 data bytes and, unless c is 0xFF
    or the block ends, by a zero."""
    out = bytearray()
    i = 0
    while i < len(block):
        code = block[i]
        if code == 0 or i + code > len(block):
            return None
        out += block[i + 1 : i + code]
        i += code
        if code != 0xFF and i < len(block):
            out.append(0)
    return bytes(out)


def decode_stream(data: bytes) -> dict:
    """Frames and counts of a byte stream, from DESIGN.md section 3's layout."""
    frames, crc_errors, malformed = [], 0, 0
    for segment in data.split(b"\x00"):
        if not segment:
            continue
        body = cobs_decode(segment)
        if body is None or len(body) < 10:
            malformed += 1
            continue
        payload, crc = body[:-2], struct.unpack("<H", body[-2:])[0]
        if binascii.crc_hqx(payload, 0xFFFF) != crc:
            crc_errors += 1
            continue
        version, kind, seq, t_us = struct.unpack_from("<BBHI", payload, 0)
        assert version == 1
        if kind == 1:
            n, status, tx_drops, pressure = struct.unpack_from("<BBHi", payload, 8)
            assert len(payload) == 16 + 2 * n
            adc = np.frombuffer(payload, dtype="<u2", count=n, offset=16)
            frames.append({"type": "SAMPLE", "seq": seq, "t_us": t_us, "status": status, "tx_drops": tx_drops,
                           "pressure_pa": pressure, "adc": adc})
        elif kind == 2:
            n, bits, rate, vref = struct.unpack_from("<BBHH", payload, 8)
            frames.append({"type": "HELLO", "seq": seq, "t_us": t_us, "n_channels": n, "adc_bits": bits,
                           "rate_hz": rate, "vref_mv": vref, "firmware": payload[14:].decode("ascii")})
        elif kind == 3:
            frames.append({"type": "TEXT", "seq": seq, "t_us": t_us, "text": payload[8:].decode("utf-8")})
        else:
            malformed += 1
    lost, last = 0, None
    for f in frames:
        if last is not None:
            lost += (f["seq"] - last - 1) % 65536
        last = f["seq"]
    return {"frames": frames, "crc_errors": crc_errors, "malformed": malformed, "lost": lost}


def unwrap(values, modulus) -> np.ndarray:
    values = np.asarray(values, dtype=np.int64)
    return values[0] + np.concatenate([[0], np.cumsum(np.diff(values) % modulus)])


@pytest.fixture(scope="module")
def stream():
    return decode_stream(STREAM.read_bytes())


@pytest.fixture(scope="module")
def samples(stream):
    return [f for f in stream["frames"] if f["type"] == "SAMPLE"]


# --------------------------------------------------------------------------- the byte stream


def test_stream_holds_what_the_board_sent(stream, samples):
    kinds = [f["type"] for f in stream["frames"]]
    assert kinds[0] == "HELLO" and kinds.count("HELLO") == 1 and kinds.count("TEXT") == 1
    assert len(samples) == SAMPLES
    assert (stream["crc_errors"], stream["malformed"], stream["lost"]) == (4, 0, 11)
    hello = stream["frames"][0]
    assert (hello["n_channels"], hello["adc_bits"], hello["rate_hz"], hello["vref_mv"], hello["firmware"]) == (
        N_CHANNELS, 12, 1000, 3300, "bendsense-sim 1")
    assert {len(s["adc"]) for s in samples} == {N_CHANNELS}
    assert max(int(s["adc"].max()) for s in samples) < 2**12
    # the run crosses both wraps: the u16 sequence number and the u32 device clock
    seq = np.array([s["seq"] for s in samples])
    t_us = np.array([s["t_us"] for s in samples])
    assert np.count_nonzero(np.diff(seq) < 0) == 1 and np.count_nonzero(np.diff(t_us) < 0) == 1
    assert np.all(np.diff(unwrap(t_us, 2**32)) > 0)
    assert sum(s["pressure_pa"] == NO_PRESSURE for s in samples) == 8


@pytest.mark.parametrize("chunk", [1, 7, 64, 4096, None])
def test_decoder_reads_the_stream_as_design_says(stream, samples, chunk):
    data = STREAM.read_bytes()
    decoder = Decoder()
    step = chunk or len(data)
    frames = [f for i in range(0, len(data), step) for f in decoder.feed(data[i : i + step])]
    got = [f for f in frames if type(f) is Sample]
    assert len(got) == len(samples)
    for g, s in zip(got, samples):
        assert (g.seq, g.t_us, g.n_channels, g.status, g.tx_drops) == (
            s["seq"], s["t_us"], N_CHANNELS, s["status"], s["tx_drops"])
        assert g.pressure_pa == (None if s["pressure_pa"] == NO_PRESSURE else s["pressure_pa"])
        assert g.adc == tuple(s["adc"].tolist())
    assert (decoder.crc_errors, decoder.malformed, decoder.lost) == (
        stream["crc_errors"], stream["malformed"], stream["lost"])
    assert decoder.frames == len(stream["frames"])
    hello = [f for f in frames if type(f) is Hello]
    assert len(hello) == 1 and hello[0].to_dict() == {k: stream["frames"][0][k] for k in hello[0].to_dict()}
    assert [f.text for f in frames if type(f) is Text] == ["fixture: a log line from the firmware"]


# --------------------------------------------------------------------------- the native session


@pytest.fixture(scope="module")
def raw_records():
    """``frames.bin`` read with DESIGN.md's record layout, not with the reader."""
    data = (SESSION / "frames.bin").read_bytes()
    dtype = np.dtype([(name, spec) for name, spec in RECORD_V2])
    assert dtype.itemsize == 57 and len(data) % dtype.itemsize == 0
    return np.frombuffer(data, dtype=dtype)


def test_session_meta_is_format_version_2():
    meta = yaml.safe_load((SESSION / "meta.yaml").read_text(encoding="utf-8"))
    assert (meta["format"], meta["version"], meta["finished"]) == ("bendsense-session", 2, True)
    assert (meta["n_channels"], meta["adc_bits"], meta["record_size"]) == (N_CHANNELS, 12, 57)
    assert meta["n_records"] == SAMPLES
    assert meta["record_dtype"] == RECORD_V2
    assert meta["device"]["firmware"] == "bendsense-sim 1"


def test_session_reads_as_recorded(raw_records):
    s = read_session(SESSION)
    assert len(s) == len(raw_records) == SAMPLES
    assert s.n_channels == N_CHANNELS and s.meta["version"] == 2 and s.meta["torn_bytes"] == 0
    np.testing.assert_array_equal(s.signals, raw_records["adc"].astype(float))
    # time: the driver removed the u32 wrap of the device clock, the reader counts from the first frame
    t_us = raw_records["t_us"].astype(np.int64)
    assert t_us.max() > 2**32 > t_us.min()
    assert np.all(np.diff(s.t_s) > 0)
    np.testing.assert_allclose(s.t_s, (t_us - t_us[0]) * 1e-6, rtol=0, atol=1e-12)
    # sequence: raw u16 on disk, unwrapped in the session
    assert np.count_nonzero(np.diff(raw_records["seq"].astype(np.int64)) < 0) == 1
    np.testing.assert_array_equal(s.seq, unwrap(raw_records["seq"], 65536))
    assert s.seq[0] == 65417 and s.seq[-1] == 65536 + 181
    # the 11 samples lost on the way, and the sequence number of the TEXT sent in between
    assert s.meta["frames_lost"] == s.seq[-1] - s.seq[0] + 1 - len(s) == 11 + 1
    assert s.meta["tx_drops"] == 7
    missing = raw_records["pressure_pa"] == NO_PRESSURE
    assert np.count_nonzero(missing) == 8
    np.testing.assert_array_equal(np.isnan(s.pressure_pa), missing)
    np.testing.assert_array_equal(s.pressure_pa[~missing], raw_records["pressure_pa"][~missing])
    np.testing.assert_array_equal(s.extra["status"], raw_records["status"])
    np.testing.assert_array_equal(s.extra["tx_drops"], raw_records["tx_drops"])
    assert np.all(np.diff(s.extra["host_s"]) >= 0)


def test_session_records_are_the_streams_samples(raw_records, samples):
    # the recorder wrote what the driver read: the same samples, field by field
    assert len(raw_records) == len(samples)
    for name in ("seq", "status", "tx_drops", "pressure_pa"):
        np.testing.assert_array_equal(raw_records[name], [s[name] for s in samples], err_msg=name)
    np.testing.assert_array_equal(raw_records["t_us"] % 2**32, [s["t_us"] for s in samples])
    np.testing.assert_array_equal(raw_records["adc"], np.stack([s["adc"] for s in samples]))


def test_session_layout_is_todays_writers(raw_records):
    records, meta = read_records(SESSION)
    assert records.dtype == record_dtype(N_CHANNELS) == raw_records.dtype
    assert records.tobytes() == raw_records.tobytes() and meta["records_recorded"] == SAMPLES


def test_session_exports_to_csv(tmp_path):
    export_session_csv(SESSION, tmp_path / "s.csv")
    s, back = read_session(SESSION), read_session_csv(tmp_path / "s.csv")
    np.testing.assert_array_equal(back.signals, s.signals)
    np.testing.assert_array_equal(back.t_s, s.t_s)
    np.testing.assert_array_equal(back.pressure_pa, s.pressure_pa)
    np.testing.assert_array_equal(back.seq, s.seq)
    assert list(back.extra) == ["host_s", "status", "tx_drops"]
