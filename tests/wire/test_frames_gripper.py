"""SAMPLE version 2 (several pressure lines) and SETPOINT (type 19), DESIGN.md sections 2b and 3.

Frames are built by hand here (struct, binascii.crc_hqx and a COBS encoder written from
its definition), independently of bendsense's encoders.
"""

import binascii
import math
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bendsense.errors import FrameError
from bendsense.wire.frames import (
    NO_PRESSURE,
    Decoder,
    FrameType,
    Sample,
    Setpoint,
    decode_frame,
    encode_frame,
    encode_sample,
    encode_setpoint,
    encode_text,
)

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def cobs(data: bytes) -> bytes:
    """COBS from its definition: each block is (distance to the next zero) + the non-zero bytes."""
    out, block = bytearray(), bytearray()
    for b in data:
        if b == 0:
            out += bytes([len(block) + 1]) + block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out += b"\xff" + block
                block = bytearray()
    out += bytes([len(block) + 1]) + block
    return bytes(out)


def wire(payload: bytes) -> bytes:
    return b"\x00" + cobs(payload + struct.pack("<H", binascii.crc_hqx(payload, 0xFFFF))) + b"\x00"


def v2_payload(seq, t_us, adc, lines, status=0, tx_drops=0, offset12=None, n_lines=None):
    p0 = lines[0] if offset12 is None else offset12
    head = struct.pack("<BBHIBBHi", 2, 1, seq, t_us, len(adc), status, tx_drops, p0)
    nl = len(lines) if n_lines is None else n_lines
    return head + struct.pack(f"<{len(adc)}H", *adc) + struct.pack(f"<B{len(lines)}i", nl, *lines)


# ----------------------------------------------------------------- SAMPLE version 2


def test_sample_v2_layout_matches_design_table():
    adc = list(range(300, 348))
    lines = [41_000, -5, 120_000]
    payload = v2_payload(0x4321, 0xCAFEBABE, adc, lines, status=0b0010, tx_drops=3)
    assert len(payload) == 16 + 2 * 48 + 1 + 4 * 3
    assert encode_sample(0x4321, 0xCAFEBABE, adc, status=2, tx_drops=3, pressures_pa=[41_000.2, -5, 120_000]) \
        == wire(payload)
    f = decode_frame(wire(payload))
    assert f == Sample(0x4321, 0xCAFEBABE, 48, 2, 3, 41_000, tuple(adc), (41_000, -5, 120_000))
    assert f.pressure_pa == 41_000 and f.pressures_pa == (41_000, -5, 120_000)


def test_version_1_reader_finds_line_0_in_a_v2_frame():
    # what today's firmware-side readers do: the fixed head at offsets 0..15, adc from 16
    frame = encode_sample(7, 1000, [11, 22, 33], pressures_pa=[55_000, 66_000])
    body = cobs_decode_reference(frame.strip(b"\x00"))
    version, ftype, seq, t_us, n, status, drops, p = struct.unpack_from("<BBHIBBHi", body)
    assert (version, ftype, seq, n, p) == (2, 1, 7, 3, 55_000)
    assert struct.unpack_from("<3H", body, 16) == (11, 22, 33)
    assert binascii.crc_hqx(body[:-2], 0xFFFF) == struct.unpack("<H", body[-2:])[0]


def cobs_decode_reference(enc: bytes) -> bytes:
    out, i = bytearray(), 0
    while i < len(enc):
        code = enc[i]
        out += enc[i + 1 : i + code]
        i += code
        if code < 0xFF and i < len(enc):
            out.append(0)
    return bytes(out)


def test_v2_no_reading_per_line_and_version_1_unchanged():
    f = decode_frame(wire(v2_payload(1, 2, [5], [NO_PRESSURE, 30_000])))
    assert f.pressures_pa == (None, 30_000) and f.pressure_pa is None
    assert encode_sample(1, 2, [5], pressures_pa=[None, 30_000]) == wire(v2_payload(1, 2, [5], [NO_PRESSURE, 30_000]))
    one = decode_frame(encode_sample(1, 2, [5], pressure_pa=30_000))
    assert one.pressures_pa == () and one.pressure_pa == 30_000  # version 1: no lines
    v1 = struct.pack("<BBHIBBHiH", 1, 1, 1, 2, 1, 0, 0, 30_000, 5)
    assert encode_sample(1, 2, [5], pressure_pa=30_000) == wire(v1)
    # a Sample with lines re-encodes as version 2, one without as version 1
    for s in (Sample(3, 4, 2, 0, 0, 9, (1, 2), (9, None, 12)), Sample(3, 4, 2, 0, 0, 9, (1, 2))):
        assert decode_frame(encode_frame(s)) == s


@SETTINGS
@given(st.integers(1, 64), st.lists(st.one_of(st.none(), st.integers(-(2**31), NO_PRESSURE - 1)), min_size=1,
                                    max_size=255), st.integers(0, 65535))
def test_v2_round_trip(n, lines, seq):
    adc = [(7 * k) % 4096 for k in range(n)]
    f = decode_frame(encode_sample(seq, 9, adc, pressures_pa=lines))
    assert f.pressures_pa == tuple(lines) and f.pressure_pa == lines[0] and f.adc == tuple(adc)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"pressures_pa": []}, r"pressures_pa: expected 1..255 pressure lines, got 0"),
        ({"pressures_pa": [0] * 256}, r"pressures_pa: expected 1..255 pressure lines, got 256"),
        ({"pressures_pa": [1, 2**31]}, r"pressures_pa\[1\]: expected -2\*\*31 <= p < 2\*\*31-1"),
        ({"pressures_pa": [1, "x"]}, r"pressures_pa\[1\]: expected a pressure \[Pa\]"),
        ({"pressures_pa": [1, 2], "pressure_pa": 5}, r"pressure_pa: 5 differs from line 0 of pressures_pa"),
    ],
)
def test_encode_v2_errors(kwargs, match):
    with pytest.raises(FrameError, match=match):
        encode_sample(0, 0, [1], **kwargs)


# ----------------------------------------------------------------- SETPOINT


def test_setpoint_layout_and_decoding():
    payload = struct.pack("<BBHIBi", 1, 19, 12, 3456, 2, 85_000)
    assert FrameType.SETPOINT == 19
    assert encode_setpoint(2, 85_000.4, seq=12, t_us=3456) == wire(payload)
    assert encode_setpoint(0, 0) == wire(struct.pack("<BBHIBi", 1, 19, 0, 0, 0, 0))
    assert decode_frame(wire(payload)) == Setpoint(12, 3456, 2, 85_000)
    assert decode_frame(encode_frame(Setpoint(1, 2, 254, -3))) == Setpoint(1, 2, 254, -3)


@pytest.mark.parametrize(
    "line, p, match",
    [
        (255, 0, r"line: expected a pressure line 0..254, got 255"),
        (-1, 0, r"line: expected a pressure line 0..254, got -1"),
        (1.5, 0, r"line: expected a pressure line 0..254, got 1.5"),
        (True, 0, r"line: expected a pressure line 0..254, got True"),
        (0, math.nan, r"pressure_pa: expected a finite set-point \[Pa\], got nan"),
        (0, math.inf, r"pressure_pa: expected a finite set-point \[Pa\], got inf"),
        (0, None, r"pressure_pa: expected a finite set-point \[Pa\], got None"),
        (0, "1000", r"pressure_pa: expected a finite set-point \[Pa\], got '1000'"),
        (0, 1e12, r"pressure_pa: expected -2\*\*31 <= p < 2\*\*31-1 \[Pa\], got 1000000000000.0"),
    ],
)
def test_encode_setpoint_errors(line, p, match):
    with pytest.raises(FrameError, match=match):
        encode_setpoint(line, p)


# ----------------------------------------------------------------- the stream decoder


def test_decoder_counts_bad_v2_and_setpoints_and_keeps_going():
    good = wire(v2_payload(1, 10, [1, 2], [100, 200]))
    sp = wire(struct.pack("<BBHIBi", 1, 19, 0, 0, 3, 40_000))
    bad = [
        wire(v2_payload(2, 11, [1, 2], [100, 200])[:-3]),  # truncated inside the lines
        wire(v2_payload(2, 11, [1, 2], [100, 200], n_lines=3)),  # n_lines > what the payload holds
        wire(v2_payload(2, 11, [1, 2], [100, 200], n_lines=1)),  # n_lines < what the payload holds
        wire(v2_payload(2, 11, [1, 2], [100], n_lines=0)[:-4]),  # no line at all
        wire(v2_payload(2, 11, [1, 2], [100, 200], offset12=101)),  # offset 12 disagrees with line 0
        wire(v2_payload(2, 11, [1, 2], [100, 200])[:16]),  # the head only
        wire(struct.pack("<BBHIBBHi", 2, 1, 2, 11, 65, 0, 0, 0) + bytes(131) + struct.pack("<Bi", 1, 0)),  # 65 ch
        wire(struct.pack("<BBHI", 2, 3, 2, 11) + b"text of version 2"),  # version 2 is a SAMPLE only
        wire(struct.pack("<BBHIBi", 1, 19, 0, 0, 255, 0)),  # line 255
        wire(struct.pack("<BBHIBi", 1, 19, 0, 0, 0, NO_PRESSURE)),  # no-reading as a target
        wire(struct.pack("<BBHIBiB", 1, 19, 0, 0, 0, 5, 0)),  # a byte too many
        wire(struct.pack("<BBHIB", 1, 19, 0, 0, 0)),  # too short
    ]
    d = Decoder(adc_bits=12)
    out = d.feed(good + b"".join(bad) + sp + wire(v2_payload(2, 12, [1, 2], [300, NO_PRESSURE])))
    assert [type(f) for f in out] == [Sample, Setpoint, Sample]
    assert out[1] == Setpoint(0, 0, 3, 40_000)
    assert out[2].pressures_pa == (300, None)
    assert (d.malformed, d.crc_errors, d.frames) == (len(bad), 0, 3)
    assert d.lost == 0  # the host's SETPOINT is not a device frame: no gap from its seq 0
    d.feed(wire(v2_payload(3, 13, [1, 2], [100, 200], offset12=101))[:-1] + b"\x01\x00")  # CRC broken
    assert d.crc_errors + d.malformed == len(bad) + 1


def test_decoder_adc_bits_checks_v2_counts():
    d = Decoder(adc_bits=12)
    assert d.feed(wire(v2_payload(0, 0, [4096], [1]))) == []
    assert d.malformed == 1


def test_setpoint_between_device_frames_is_no_gap():
    d = Decoder()
    d.feed(encode_text(10, 0, "a") + encode_setpoint(1, 5, seq=500) + encode_text(11, 0, "b"))
    assert d.lost == 0 and d.frames == 3
    d.feed(encode_text(13, 0, "c"))
    assert d.lost == 1  # and a real gap still counts


@SETTINGS
@given(st.binary(max_size=400))
def test_decoder_never_raises_on_v2_like_bytes(junk):
    d = Decoder()
    frame = encode_sample(1, 2, [3, 4], pressures_pa=[5, 6])
    d.feed(junk + frame + junk[: len(junk) // 2] + b"\x00" + encode_setpoint(1, 2) + junk)
    assert d.frames >= 0 and d.errors >= 0


@SETTINGS
@given(st.integers(0, 80), st.binary(min_size=1, max_size=20))
def test_decoder_never_raises_on_damaged_v2(cut, noise):
    payload = v2_payload(5, 6, [1, 2, 3], [7, 8, 9])
    damaged = payload[:cut] + noise + payload[cut + len(noise):]
    d = Decoder()
    out = d.feed(wire(damaged))
    assert len(out) + d.malformed == 1
    if out and isinstance(out[0], Sample) and out[0].pressures_pa:  # a v2 that decodes agrees with itself
        assert out[0].pressures_pa[0] == out[0].pressure_pa


def test_longest_legal_frame_fits_the_default_decoder():
    lines = [(-1) ** k * 1000 * k for k in range(255)]
    frame = wire(v2_payload(9, 9, [4095] * 64, lines))
    assert len(frame) > 1024  # longer than a version-1 frame can be
    out = Decoder().feed(frame)
    assert len(out) == 1 and out[0].pressures_pa == tuple(lines) and out[0].adc == (4095,) * 64


def test_a_sequence_as_pressure_pa_sends_version_2():
    # a frame source that gives one pressure per line (e.g. a replayed gripper session) gets version 2 from any
    # caller of encode_sample, NaN meaning no reading
    import numpy as np

    assert encode_sample(1, 2, [5], np.array([20_000.0, np.nan])) == wire(v2_payload(1, 2, [5], [20_000, NO_PRESSURE]))
    assert encode_sample(1, 2, [5], (7, 8)) == encode_sample(1, 2, [5], pressures_pa=[7, 8])
