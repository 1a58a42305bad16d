"""Frozen files of a gripper's board still load: SAMPLE version 2 (three pressure lines) and its session.

``tests/data/formats/make.py lines`` wrote them once (a replayed three-line session with
dropped and corrupted frames): ``stream_v2_lines.bin``, the bytes the driver read, and
``session_v2_lines/``, what the recorder wrote. They are read here with the public readers
and compared with a decoder written from DESIGN.md sections 2b and 3 alone.
"""

from __future__ import annotations

import binascii
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml

from bendsense import read_session, read_session_csv
from bendsense.session.native import export_session_csv
from bendsense.wire.frames import Decoder, Hello, Sample
from integration.test_formats_frozen import cobs_decode  # the independent COBS decoder of the version-1 files

DATA = Path(__file__).parents[1] / "data" / "formats"
NO_PRESSURE = 0x7FFFFFFF
RECORD = [["host_ns", "<i8"], ["t_us", "<u8"], ["seq", "<u2"], ["status", "|u1"], ["tx_drops", "<u2"],
          ["pressure_pa", "<i4"], ["adc", "(8,)<u2"], ["pressures_pa", "(3,)<i4"]]


def v2_samples(data: bytes) -> list:
    """The SAMPLEs of a stream, by DESIGN.md: after adc[n], u8 n_lines and i32 pressure_pa[n_lines]."""
    out = []
    for segment in data.split(b"\x00"):
        body = cobs_decode(segment) if segment else None
        if body is None or len(body) < 10 or binascii.crc_hqx(body[:-2], 0xFFFF) != struct.unpack("<H", body[-2:])[0]:
            continue
        payload = body[:-2]
        version, kind, seq, t_us = struct.unpack_from("<BBHI", payload)
        if kind != 1:
            continue
        assert version == 2
        n, status, tx_drops, p0 = struct.unpack_from("<BBHi", payload, 8)
        n_lines = payload[16 + 2 * n]
        assert len(payload) == 16 + 2 * n + 1 + 4 * n_lines
        lines = struct.unpack_from(f"<{n_lines}i", payload, 17 + 2 * n)
        assert lines[0] == p0
        out.append({"seq": seq, "t_us": t_us, "status": status, "adc": struct.unpack_from(f"<{n}H", payload, 16),
                    "lines": lines})
    return out


@pytest.fixture(scope="module")
def stream():
    return (DATA / "stream_v2_lines.bin").read_bytes()


def test_stream_decodes_as_design_says(stream):
    expected = v2_samples(stream)
    assert len(expected) == 140
    for chunk in (1, 7, len(stream)):
        dec = Decoder()
        frames = [f for k in range(0, len(stream), chunk) for f in dec.feed(stream[k:k + chunk])]
        got = [f for f in frames if type(f) is Sample]
        assert [type(f) for f in frames if type(f) is not Sample] == [Hello]
        assert [(s.seq, s.t_us, s.status, s.adc) for s in got] == [
            (e["seq"], e["t_us"], e["status"], e["adc"]) for e in expected]
        assert [s.pressures_pa for s in got] == [tuple(None if v == NO_PRESSURE else v for v in e["lines"])
                                                 for e in expected]
        assert (dec.crc_errors, dec.malformed, dec.lost) == (5, 0, 10)


def test_session_layout_and_lines(stream):
    meta = yaml.safe_load((DATA / "session_v2_lines" / "meta.yaml").read_text())
    assert (meta["version"], meta["n_lines"], meta["record_dtype"], meta["record_size"]) == (2, 3, RECORD, 53)
    records = np.fromfile(DATA / "session_v2_lines" / "frames.bin", dtype=np.dtype([tuple(f) for f in RECORD]))
    expected = v2_samples(stream)
    np.testing.assert_array_equal(records["pressures_pa"], [e["lines"] for e in expected])
    np.testing.assert_array_equal(records["pressure_pa"], records["pressures_pa"][:, 0])
    s = read_session(DATA / "session_v2_lines")
    lines = np.array([e["lines"] for e in expected], dtype=float)
    lines[lines == NO_PRESSURE] = np.nan
    np.testing.assert_array_equal(s.pressure_pa, lines)
    # what make.py's session gave frame k (seq k - 60, mod 65536): the replayed lines, no reading where it had none
    k = (np.array([e["seq"] for e in expected]) + 60) % 65536
    want = np.column_stack([20_000.0 + 100.0 * k, 30_000.0 + 50.0 * k, 40_000.0 - 20.0 * k])
    want[k % 23 == 4, 2] = np.nan
    want[k % 41 == 7, 0] = np.nan
    np.testing.assert_array_equal(s.pressure_pa, want)
    np.testing.assert_array_equal(s.signals, (k[:, None] * 13 + 211 * np.arange(8)[None, :]) % 4096)
    np.testing.assert_array_equal(s.signals, [e["adc"] for e in expected])
    assert s.meta["frames_lost"] == 10


def test_session_exports_lines(tmp_path):
    export_session_csv(DATA / "session_v2_lines", tmp_path / "g.csv")
    header = next(line for line in (tmp_path / "g.csv").read_text().splitlines() if not line.startswith("#"))
    assert header.startswith("t_s,line0_pressure_pa,line1_pressure_pa,line2_pressure_pa,ch1,")
    np.testing.assert_array_equal(read_session_csv(tmp_path / "g.csv").pressure_pa,
                                  read_session(DATA / "session_v2_lines").pressure_pa)
