"""Wire protocol: CRC, COBS, payload layout (DESIGN.md section 3) and the incremental decoders."""

import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bendsense.errors import FrameError
from bendsense.wire.frames import (
    NO_PRESSURE,
    Command,
    Decoder,
    FrameType,
    Hello,
    LineDecoder,
    Sample,
    Text,
    cobs_decode,
    cobs_encode,
    crc16_ccitt_false,
    decode_frame,
    encode_command,
    encode_frame,
    encode_hello,
    encode_sample,
    encode_text,
)

SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# ----------------------------------------------------------------- independent references


def crc_reference(data: bytes) -> int:
    """Bitwise CRC-16/CCITT-FALSE straight from its definition."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def cobs_decode_reference(enc: bytes) -> bytes:
    out, i = [], 0
    while i < len(enc):
        code = enc[i]
        assert code != 0
        out += list(enc[i + 1 : i + code])
        assert i + code <= len(enc)
        i += code
        if code < 0xFF and i < len(enc):
            out.append(0)
    return bytes(out)


def wire(payload: bytes) -> bytes:
    """Frame a payload by hand (CRC little-endian, COBS from the reference-checked encoder)."""
    body = payload + struct.pack("<H", crc_reference(payload))
    return b"\x00" + cobs_encode(body) + b"\x00"


# ----------------------------------------------------------------- primitives


def test_crc_check_value():
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc_reference(b"123456789") == 0x29B1


@SETTINGS
@given(st.binary(max_size=300))
def test_crc_matches_bitwise_definition(data):
    assert crc16_ccitt_false(data) == crc_reference(data)


@SETTINGS
@given(st.binary(max_size=700))
def test_cobs_round_trip(data):
    enc = cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + 1 + len(data) // 254 + 1
    assert cobs_decode_reference(enc) == data
    assert cobs_decode(enc) == data


def test_cobs_known_vectors():
    # vectors from the COBS paper / Wikipedia
    assert cobs_encode(b"\x00") == b"\x01\x01"
    assert cobs_encode(b"\x00\x00") == b"\x01\x01\x01"
    assert cobs_encode(b"\x11\x22\x00\x33") == b"\x03\x11\x22\x02\x33"
    assert cobs_encode(b"\x11\x00\x00\x00") == b"\x02\x11\x01\x01\x01"
    assert cobs_decode(b"\xff" + bytes(range(1, 255))) == bytes(range(1, 255))


@pytest.mark.parametrize("bad", [b"", b"\x05\x01", b"\x02\x00\x01"])
def test_cobs_decode_rejects(bad):
    with pytest.raises(FrameError, match="COBS"):
        cobs_decode(bad)


# ----------------------------------------------------------------- payload layout


def test_sample_layout_matches_design_table():
    adc = list(range(100, 116))
    payload = struct.pack("<BBHIBBHi", 1, 1, 0x1234, 0xDEADBEEF, 16, 0b1001, 7, -250) + struct.pack("<16H", *adc)
    assert encode_sample(0x1234, 0xDEADBEEF, adc, pressure_pa=-250, status=0b1001, tx_drops=7) == wire(payload)
    frame = decode_frame(wire(payload))
    assert frame == Sample(0x1234, 0xDEADBEEF, 16, 9, 7, -250, tuple(adc))


def test_no_pressure_and_wrapping_on_encode():
    f = decode_frame(encode_sample(65536 + 3, 2**32 + 5, [1], pressure_pa=None))
    assert (f.seq, f.t_us, f.pressure_pa) == (3, 5, None)
    raw = cobs_decode(encode_sample(0, 0, [1], pressure_pa=float("nan")).strip(b"\x00"))
    assert struct.unpack_from("<i", raw, 12)[0] == NO_PRESSURE


def test_hello_text_command_layout():
    payload = struct.pack("<BBHIBBHH", 1, 2, 9, 1000, 16, 12, 500, 3300) + b"fw-1.2"
    assert encode_hello(9, 1000, 16, 12, 500, 3300, "fw-1.2") == wire(payload)
    assert decode_frame(wire(payload)) == Hello(9, 1000, 16, 12, 500, 3300, "fw-1.2")
    payload = struct.pack("<BBHI", 1, 3, 10, 2000) + "température ok".encode()
    assert encode_text(10, 2000, "température ok") == wire(payload)
    for kind, code in [("start", 16), ("stop", 17), ("hello_request", 18), ("heartbeat", 20)]:
        assert encode_command(kind) == wire(struct.pack("<BBHI", 1, code, 0, 0))
        assert decode_frame(encode_command(kind)) == Command(FrameType(code), 0, 0)


def test_encode_frame_round_trip_of_objects():
    frames = [
        Sample(1, 2, 3, 4, 5, None, (6, 7, 8)),
        Hello(2, 3, 16, 12, 500, 3300, "x"),
        Text(3, 4, "hi"),
        Command(FrameType.STOP, 1, 0),
    ]
    for f in frames:
        assert decode_frame(encode_frame(f)) == f


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"adc": []}, "adc: expected 1..64 channels, got 0"),
        ({"adc": [0] * 65}, "adc: expected 1..64 channels, got 65"),
        ({"adc": [70000]}, "adc: counts must be in 0..65535"),
        ({"adc": [1], "pressure_pa": 2**31}, "pressure_pa"),
        ({"adc": [1], "status": 256}, "status"),
    ],
)
def test_encode_sample_errors(kwargs, match):
    with pytest.raises(FrameError, match=match):
        encode_sample(0, 0, **kwargs)


def test_encode_other_errors():
    with pytest.raises(FrameError, match="firmware: at most 32"):
        encode_hello(0, 0, 16, 12, 500, 3300, "x" * 33)
    with pytest.raises(FrameError, match="adc_bits"):
        encode_hello(0, 0, 16, 17, 500, 3300)
    with pytest.raises(FrameError, match="command kind"):
        encode_command("reboot")


# ----------------------------------------------------------------- Decoder: strategies

seqs = st.integers(0, 65535)
times = st.integers(0, 2**32 - 1)


@st.composite
def samples(draw):
    n = draw(st.integers(1, 64))
    adc = tuple(draw(st.lists(st.integers(0, 65535), min_size=n, max_size=n)))
    p = draw(st.one_of(st.none(), st.integers(-(2**31), NO_PRESSURE - 1)))
    return Sample(draw(seqs), draw(times), n, draw(st.integers(0, 255)), draw(st.integers(0, 65535)), p, adc)


hellos = st.builds(
    Hello,
    seqs,
    times,
    st.integers(1, 64),
    st.just(16),  # 16 bits: a HELLO must not make later random samples out of range
    st.integers(0, 65535),
    st.integers(0, 65535),
    st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=32),
)
texts = st.builds(Text, seqs, times, st.text(max_size=80))
commands = st.builds(Command, st.sampled_from([FrameType.START, FrameType.STOP, FrameType.HELLO_REQUEST,
                                                FrameType.HEARTBEAT]), seqs, times)
any_frame = st.one_of(samples(), samples(), hellos, texts, commands)


def cut(data: bytes, points) -> list:
    points = sorted({p % (len(data) + 1) for p in points})
    edges = [0, *points, len(data)]
    return [data[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]


def expected_lost(frames) -> int:
    lost, last = 0, None
    for f in frames:
        if isinstance(f, Command):
            continue
        if last is not None:
            lost += (f.seq - last - 1) % 65536
        last = f.seq
    return lost


@SETTINGS
@given(st.lists(any_frame, max_size=25), st.lists(st.integers(0, 10**6), max_size=30))
def test_decoder_round_trip_under_any_chunking(frames, points):
    stream = b"".join(encode_frame(f) for f in frames)
    dec = Decoder()
    out = []
    for chunk in cut(stream, points):
        out += dec.feed(chunk)
    assert out == frames
    assert (dec.frames, dec.crc_errors, dec.malformed) == (len(frames), 0, 0)
    assert dec.lost == expected_lost(frames)


def test_sequence_gaps_and_wrap():
    dec = Decoder()
    stream = b"".join(encode_sample(s, 0, [1]) for s in [65533, 65534, 65535, 0, 1, 5, 6, 65530])
    frames = dec.feed(stream)
    assert [f.seq for f in frames] == [65533, 65534, 65535, 0, 1, 5, 6, 65530]
    # 1 -> 5 loses 3; 6 -> 65530 loses 65523
    assert dec.lost == 3 + 65523
    assert list(dec.gaps) == [(5, 3), (65530, 65523)]
    # HELLO and TEXT count in the device sequence, commands do not
    dec = Decoder()
    dec.feed(encode_hello(10, 0, 1, 12, 500, 3300) + encode_command("start", seq=99) + encode_text(11, 0, "x"))
    dec.feed(encode_sample(12, 0, [1]))
    assert dec.lost == 0


# ----------------------------------------------------------------- Decoder: damage


@st.composite
def damaged_streams(draw):
    """Frames, some damaged: returns the stream and the intact frames in order."""
    n = draw(st.integers(1, 12))
    pieces, intact = [], []
    for i in range(n):
        f = Sample(i, 1000 * i, 4, 0, 0, 100, (1, 2, 300, 4000))
        enc = encode_frame(f)
        kind = draw(st.sampled_from(["ok", "ok", "flip", "truncate", "garbage", "drop_lead"]))
        if kind == "ok":
            pieces.append(enc)
            intact.append(f)
        elif kind == "flip":
            pos = draw(st.integers(0, len(enc) - 1))
            bit = draw(st.integers(0, 7))
            b = bytearray(enc)
            b[pos] ^= 1 << bit
            pieces.append(bytes(b))
        elif kind == "truncate":
            pieces.append(enc[: draw(st.integers(0, len(enc) - 1))])
        elif kind == "garbage":
            pieces.append(draw(st.binary(max_size=60)))
            pieces.append(enc)
            intact.append(f)
        else:  # frame without its leading delimiter: only found if the previous piece ended with 0x00
            pieces.append(enc[1:])
    return b"".join(pieces), pieces, intact


@SETTINGS
@given(damaged_streams(), st.lists(st.integers(0, 10**5), max_size=20))
def test_damage_never_raises_nor_loses_intact_frames(case, points):
    stream, _pieces, intact = case
    dec = Decoder()
    out = []
    for chunk in cut(stream, points):
        out += dec.feed(chunk)
    # every intact frame (it begins with a delimiter) is recovered, in order
    it = iter(out)
    assert all(any(f == g for g in it) for f in intact)


@SETTINGS
@given(st.binary(max_size=2000), st.lists(st.integers(0, 10**5), max_size=20))
def test_arbitrary_bytes_never_raise_and_chunking_does_not_matter(data, points):
    whole = Decoder(max_frame_bytes=300)
    out_whole = whole.feed(data)
    chunked = Decoder(max_frame_bytes=300)
    out_chunked = []
    for chunk in cut(data, points):
        out_chunked += chunked.feed(chunk)
    assert out_whole == out_chunked
    keys = ["frames", "crc_errors", "malformed", "overruns", "lost", "bytes"]
    assert [getattr(whole, k) for k in keys] == [getattr(chunked, k) for k in keys]


def test_each_bad_frame_is_counted_once():
    good = [encode_sample(i, 0, [i, 2 * i]) for i in range(6)]
    flipped = bytearray(good[1])
    flipped[5] ^= 0x10  # a data byte: CRC error
    truncated = good[3][:-4]
    stream = good[0] + bytes(flipped) + good[2] + truncated + good[4] + good[5]
    dec = Decoder()
    frames = dec.feed(stream)
    assert [f.seq for f in frames] == [0, 2, 4, 5]
    assert dec.crc_errors + dec.malformed == 2
    assert dec.lost == 2
    assert dec.frames + dec.lost == 6


def test_empty_frames_are_not_errors():
    dec = Decoder()
    frames = dec.feed(b"\x00\x00\x00" + encode_sample(0, 0, [1]) + b"\x00\x00" + encode_sample(1, 0, [1]) + b"\x00")
    assert len(frames) == 2 and dec.errors == 0


def payload_sample(n, adc, version=1, ftype=1, extra=b""):
    return struct.pack("<BBHIBBHi", version, ftype, 0, 0, n, 0, 0, 0) + struct.pack(f"<{len(adc)}H", *adc) + extra


@pytest.mark.parametrize(
    "payload",
    [
        payload_sample(0, []),
        payload_sample(65, [1] * 65),
        payload_sample(3, [1, 2]),  # declared 3 channels, sent 2
        payload_sample(2, [1, 2], extra=b"\x01"),  # trailing byte
        payload_sample(1, [1], version=2),
        payload_sample(1, [1], ftype=7),
        struct.pack("<BBHI", 1, 2, 0, 0),  # HELLO too short
        struct.pack("<BBHIBBHH", 1, 2, 0, 0, 0, 12, 500, 3300),  # HELLO with 0 channels
        struct.pack("<BBHIBBHH", 1, 2, 0, 0, 16, 12, 500, 3300) + b"x" * 33,  # firmware too long
        struct.pack("<BBHI", 1, 16, 0, 0) + b"x",  # command with a body
        b"\x01",
    ],
)
def test_malformed_payloads_are_counted(payload):
    dec = Decoder()
    after = encode_sample(1, 0, [5])
    frames = dec.feed(wire(payload) + after)
    assert dec.malformed == 1 and dec.crc_errors == 0
    assert frames == [decode_frame(after)]
    with pytest.raises(FrameError, match="malformed"):
        decode_frame(wire(payload))


def test_adc_range_from_hello():
    dec = Decoder()
    frames = dec.feed(
        encode_hello(0, 0, 2, 12, 500, 3300) + encode_sample(1, 0, [4095, 0]) + encode_sample(2, 0, [4096, 0])
    )
    assert [type(f).__name__ for f in frames] == ["Hello", "Sample"]
    assert dec.malformed == 1 and dec.hello.adc_bits == 12 and dec.adc_bits == 12
    assert Decoder(adc_bits=10).feed(encode_sample(0, 0, [1024])) == []


def test_over_long_run_is_dropped_with_bounded_memory():
    dec = Decoder(max_frame_bytes=256)
    junk = bytes(range(1, 256)) * 40
    for i in range(0, len(junk), 100):
        assert dec.feed(junk[i : i + 100]) == []
        assert len(dec._buf) <= 256
    frames = dec.feed(encode_sample(7, 0, [1]))
    assert [f.seq for f in frames] == [7]
    assert dec.overruns == 1 and dec.malformed == 1
    # the same in one piece
    dec = Decoder(max_frame_bytes=256)
    assert [f.seq for f in dec.feed(junk + encode_sample(7, 0, [1]))] == [7]
    assert dec.overruns == 1


def test_crc_error_counted_not_raised():
    enc = bytearray(encode_sample(0, 0, [1, 2, 3]))
    enc[-3] ^= 0x01
    dec = Decoder()
    assert dec.feed(bytes(enc)) == [] and dec.crc_errors == 1
    with pytest.raises(FrameError, match="CRC"):
        decode_frame(bytes(enc))


# ----------------------------------------------------------------- LineDecoder


def test_line_decoder_basic():
    dec = LineDecoder(n_channels=3)
    text = "# firmware 1.0\nch1,ch2,ch3\n1, 2, 3\n4 5 6\r\n7,8\nx,1,2\n\n10\t11 12.5\n"
    frames = dec.feed(text.encode())
    assert [f.adc for f in frames] == [(1, 2, 3), (4, 5, 6), (10, 11, 12.5)]
    assert [f.seq for f in frames] == [0, 1, 2]
    assert frames[0] == Sample(0, None, 3, 0, 0, None, (1, 2, 3))
    assert dec.malformed == 2 and dec.frames == 3 and dec.lost == 0


def test_line_decoder_columns_and_gaps_under_chunking():
    dec = LineDecoder(columns=("seq", "t_us", "ch2", "pressure_pa", "ch1"))
    text = b"0,100,20,5000,10\n1,200,21,nan,11\n4,500,22,5000.5,12\n"
    out = []
    for i in range(len(text)):
        out += dec.feed(text[i : i + 1])
    assert [(f.seq, f.t_us, f.pressure_pa, f.adc) for f in out] == [
        (0, 100, 5000, (10, 20)),
        (1, 200, None, (11, 21)),
        (4, 500, 5000.5, (12, 22)),
    ]
    assert dec.lost == 2


def test_line_decoder_bounded_and_errors():
    dec = LineDecoder(n_channels=1, max_line_bytes=64)
    dec.feed(b"1" * 1000)
    assert len(dec._buf) <= 64
    assert [f.adc for f in dec.feed(b"\n5\n")] == [(5,)]
    assert dec.overruns == 1
    with pytest.raises(FrameError, match="ch1..chN"):
        LineDecoder(columns=("a", "ch2"))
    with pytest.raises(FrameError, match=r"the line dialect needs its column layout: give columns .* or n_channels"):
        LineDecoder()


@SETTINGS
@given(st.binary(max_size=500))
def test_line_decoder_never_raises(data):
    LineDecoder(columns=("seq", "ch1", "ch2")).feed(data)


def test_sample_fields_table_names_sample_attributes():
    # the recorder copies each field of the table from the Sample attribute of the same name
    from bendsense.wire.frames import SAMPLE_FIELDS, Sample

    names = [f.name for f in SAMPLE_FIELDS]
    assert len(set(names)) == len(names)
    assert set(names) <= set(Sample.__dataclass_fields__) - {"n_channels", "adc"}
    assert [f.name for f in SAMPLE_FIELDS if f.since == 1] == ["t_us", "seq", "status", "pressure_pa"]
