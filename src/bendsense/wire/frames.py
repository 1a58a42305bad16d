"""Wire protocol of the sensor board: payloads and incremental decoders.

Pure functions and classes, no IO. The binary protocol is DESIGN.md section 3: each
frame on the wire is ``0x00, COBS(body), 0x00`` with ``body = payload + CRC16`` (CRC-16/
CCITT-FALSE of the payload, little-endian; :mod:`bendsense.wire.framing`, re-exported here).
Payload, little-endian::

    0  u8   version = 1 (2: a SAMPLE with several pressure lines)
    1  u8   type: 1 SAMPLE, 2 HELLO, 3 TEXT; host->device 16 START, 17 STOP, 18 HELLO_REQUEST,
            19 SETPOINT, 20 HEARTBEAT
    2  u16  seq: +1 per device frame of any type, wraps at 65536
    4  u32  t_us: device clock [us], wraps
    SAMPLE 8: u8 n_channels (1..64), u8 status, u16 tx_drops, i32 pressure_pa
              (0x7FFFFFFF = no reading), u16[n] adc; what a recording keeps of it:
              SAMPLE_FIELDS
              version 2 then: u8 n_lines (1..255), i32 pressure_pa[n_lines]; the i32 at
              offset 12 repeats line 0, so a version-1 reader still finds a pressure
    HELLO  8: u8 n_channels, u8 adc_bits, u16 rate_hz, u16 vref_mv, <= 32 B firmware (ASCII)
    TEXT   8: UTF-8 log line
    SETPOINT 8: u8 line (0..254), i32 pressure_pa (the line's target; not 0x7FFFFFFF)
    START, STOP, HELLO_REQUEST, HEARTBEAT: the header only (HEARTBEAT: "the host is alive",
              which feeds the board's host-silence watchdog)

:class:`Decoder` turns a byte stream, cut into chunks anywhere, into frame objects; it
resynchronises at the next ``0x00`` after any bad frame, counts what it rejects and never
raises on bad bytes. :class:`LineDecoder` does the same for the text dialect (one frame
per line) of simple firmware.
"""

from __future__ import annotations

import binascii
import enum
import functools
import math
import numbers
import struct
from dataclasses import dataclass
from typing import NamedTuple

from bendsense.errors import FrameError
from bendsense.wire.framing import (
    _cobs_decode,
    _StreamDecoder,
    cobs_decode,
    cobs_encode,
    crc16_ccitt_false,
    frame_bytes,
)

__all__ = [
    "VERSION",
    "VERSION_LINES",
    "MAX_LINES",
    "NO_PRESSURE",
    "FrameType",
    "StatusBits",
    "Sample",
    "SampleField",
    "SAMPLE_FIELDS",
    "Hello",
    "Text",
    "Command",
    "Setpoint",
    "crc16_ccitt_false",
    "cobs_encode",
    "cobs_decode",
    "frame_bytes",
    "encode_sample",
    "encode_hello",
    "encode_text",
    "encode_command",
    "encode_setpoint",
    "encode_frame",
    "decode_body",
    "decode_frame",
    "Decoder",
    "LineDecoder",
]

VERSION = 1
VERSION_LINES = 2
"""Version byte of a SAMPLE that carries several pressure lines (``n_lines``, ``pressure_pa[n_lines]``)."""
NO_PRESSURE = 0x7FFFFFFF
"""``pressure_pa`` on the wire when the board has no pressure reading."""
MAX_CHANNELS = 64
MAX_FIRMWARE_BYTES = 32
MAX_LINES = 255
"""Most pressure lines a SAMPLE carries (line indices 0..254)."""


class FrameType(enum.IntEnum):
    """Frame type byte (payload offset 1)."""

    SAMPLE = 1
    HELLO = 2
    TEXT = 3
    START = 16
    STOP = 17
    HELLO_REQUEST = 18
    SETPOINT = 19
    HEARTBEAT = 20


class StatusBits(enum.IntFlag):
    """Bits of the SAMPLE status byte."""

    ADC_OVERRUN = 1
    LOCKIN_SATURATED = 2
    MUX_SETTLE = 4
    TX_OVERFLOW = 8


#: The bits that say a SAMPLE's own readings are not to be used (a clipped or unsettled channel): such a frame
#: has no shape (status ``no_shape``). TX_OVERFLOW says frames were lost before it, not that it is wrong.
BAD_READING = StatusBits.ADC_OVERRUN | StatusBits.LOCKIN_SATURATED | StatusBits.MUX_SETTLE


class _Lines:
    __slots__ = ("pressures_pa",)


@dataclass(slots=True, init=False, eq=False)
class Sample(_Lines):
    """One SAMPLE frame.

    Frame classes are slotted dataclasses, not frozen ones, because building a frozen
    instance costs ~5x more and the decoder makes one per frame; treat them as read-only.
    ``pressures_pa`` is an attribute but not a dataclass field: the fields are the
    scalar values a recording keeps (:data:`SAMPLE_FIELDS`), ``n_channels`` and ``adc``.

    Attributes
    ----------
    seq : int
        Sequence number (0..65535, wraps).
    t_us : int or None
        Device clock [us] (0..2**32-1, wraps); None from a line dialect without a ``t_us`` column.
    n_channels : int
        Number of ADC values.
    status : int
        Status bits (:class:`StatusBits`).
    tx_drops : int
        Cumulative frames the firmware could not send.
    pressure_pa : int, float or None
        Actuation pressure [Pa] (of line 0 when the board has several); None for "no reading".
    adc : tuple of int
        Raw ADC counts, one per channel (floats only from a line dialect that sends them).
    pressures_pa : tuple
        One pressure [Pa] per pressure line (None: no reading) from a version-2 SAMPLE;
        ``()`` from a version-1 one (one line: ``pressure_pa``).
    """

    seq: int
    t_us: int | None
    n_channels: int
    status: int
    tx_drops: int
    pressure_pa: int | float | None
    adc: tuple

    def __init__(self, seq, t_us, n_channels, status, tx_drops, pressure_pa, adc, pressures_pa=()):
        self.seq = seq
        self.t_us = t_us
        self.n_channels = n_channels
        self.status = status
        self.tx_drops = tx_drops
        self.pressure_pa = pressure_pa
        self.adc = adc
        self.pressures_pa = pressures_pa

    def __eq__(self, other):
        if type(other) is not Sample:
            return NotImplemented
        return (self.seq, self.t_us, self.n_channels, self.status, self.tx_drops, self.pressure_pa, self.adc,
                tuple(self.pressures_pa)) == (other.seq, other.t_us, other.n_channels, other.status,
                                              other.tx_drops, other.pressure_pa, other.adc, tuple(other.pressures_pa))

    def __repr__(self):
        lines = f", pressures_pa={self.pressures_pa!r}" if self.pressures_pa else ""
        return (f"Sample(seq={self.seq!r}, t_us={self.t_us!r}, n_channels={self.n_channels!r}, "
                f"status={self.status!r}, tx_drops={self.tx_drops!r}, pressure_pa={self.pressure_pa!r}, "
                f"adc={self.adc!r}{lines})")


class SampleField(NamedTuple):
    """One scalar value of every SAMPLE, as a recording stores it (an entry of :data:`SAMPLE_FIELDS`).

    Attributes
    ----------
    name : str
        The :class:`Sample` attribute, the field of a native session's record and, for
        the fields a :class:`~bendsense.session.Session` has no column of its own for,
        the ``Session.extra`` column.
    dtype : str
        numpy dtype of the record field in ``frames.bin`` (little-endian).
    since : int
        The native session format version that first records the field.
    description : str
        What the value is, with its unit.
    """

    name: str
    dtype: str
    since: int
    description: str


SAMPLE_FIELDS = (
    #           name           record dtype  since (session version)  what
    SampleField("t_us", "<u8", 1, "device clock [us]; u32 on the wire (wraps), recorded unwrapped"),
    SampleField("seq", "<u2", 1, "sequence number, raw: +1 per device frame of any type, wraps at 65536"),
    SampleField("status", "|u1", 1, "status bits (StatusBits)"),
    SampleField("tx_drops", "<u2", 2, "cumulative frames the firmware could not send, wraps at 65536"),
    SampleField("pressure_pa", "<i4", 1, "actuation pressure [Pa]; NO_PRESSURE = no reading"),
)
"""The scalar fields of a SAMPLE, in the order a recording stores them.

A native session's record is ``host_ns`` (when the host read the bytes), these fields,
then the N ``adc`` counts. The record dtype (:func:`bendsense.session.native.record_dtype`,
and the reader's checks of it), the recorder's copy of each sample into a record
(:func:`bendsense.session.native.sample_records`) and what a recording gives a
:class:`~bendsense.session.Session` (:func:`bendsense.session.native.records_to_session`:
a field without a column of its own goes to ``Session.extra`` under its name, and from
there into the session CSV and back) are derived from this table. The wire bytes are
not: ``_SAMPLE_HEAD`` and :func:`_parse_body` spell them out, because the payload puts
``seq`` before ``t_us`` (the header every frame type shares) and the decoder's hot path
unpacks by position.

Where do I add a wire field? The SAMPLE layout is fixed by DESIGN.md section 3, so a
new field is a new protocol version, agreed there first. Then, for a board temperature
``temp_cdeg`` (i16, 0.01 °C):

1. here, one entry: ``SampleField("temp_cdeg", "<i2", 3, "board temperature [0.01 °C]")``,
   ``since`` one above :data:`bendsense.session.native.FORMAT_VERSION`;
2. here, the bytes: the new ``VERSION`` read by :func:`_parse_body` beside the old one
   (boards in the field keep sending theirs), the struct, a :class:`Sample` attribute
   with the value an old board means as its default, an argument of
   :func:`encode_sample`, and the layout in the module docstring;
3. :mod:`bendsense.session.native`: ``FORMAT_VERSION`` up by one, and the new version
   added to ``READ_VERSIONS`` (older sessions still read; their records lack the field);
4. ``tests/data/formats/``: a frozen session and byte stream of the new version beside
   the old ones (``make.py`` there writes them); the old ones must keep loading.

The record dtype, the recorder, ``Session.extra``, the session CSV export and import
follow from step 1; the simulated board sends :func:`encode_sample`'s default until
it is given a value. ``tests/session/test_native.py::test_a_new_sample_field_reaches_every_layer``
does step 1 and checks those.
"""


@dataclass(slots=True)
class Hello:
    """HELLO frame: what the board is (its answer to HELLO_REQUEST)."""

    seq: int
    t_us: int
    n_channels: int
    adc_bits: int
    rate_hz: int
    vref_mv: int
    firmware: str

    def to_dict(self) -> dict:
        """Plain dict of the fields (for ``meta.yaml``)."""
        return {
            "n_channels": self.n_channels,
            "adc_bits": self.adc_bits,
            "rate_hz": self.rate_hz,
            "vref_mv": self.vref_mv,
            "firmware": self.firmware,
        }


@dataclass(slots=True)
class Text:
    """TEXT frame: a log line from the firmware."""

    seq: int
    t_us: int
    text: str


@dataclass(slots=True)
class Command:
    """Host-to-device frame of the header only (START, STOP, HELLO_REQUEST, HEARTBEAT); no sequence gap accounting."""

    kind: FrameType
    seq: int = 0
    t_us: int = 0


@dataclass(slots=True)
class Setpoint:
    """SETPOINT frame (host to device): the target pressure of one pressure line.

    Attributes
    ----------
    seq : int
        Sequence number (the host's; the device does not check it).
    t_us : int
        Host clock [us]; the firmware may ignore it.
    line : int
        Pressure line, 0-based (0..254).
    pressure_pa : int
        Target pressure [Pa].
    """

    seq: int
    t_us: int
    line: int
    pressure_pa: int


# --------------------------------------------------------------------------- encoding

_HEADER = struct.Struct("<BBHI")
_SAMPLE_HEAD = struct.Struct("<BBHIBBHi")
_HELLO_HEAD = struct.Struct("<BBHIBBHH")
_SETPOINT_TAIL = struct.Struct("<Bi")
_SETPOINT = struct.Struct("<BBHIBi")


@functools.cache
def _adc_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<{n}H")


@functools.cache
def _lines_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<{n}i")


@functools.cache
def _sample_struct(n: int) -> struct.Struct:
    return struct.Struct(f"<BBHIBBHi{n}H")


def _check_int(name: str, value, lo: int, hi: int) -> int:
    v = int(value)
    if v != value or not lo <= v <= hi:
        raise FrameError(f"{name}: expected an integer in {lo}..{hi}, got {value!r}")
    return v


def _wire_pressure(name: str, value) -> int:
    if value is None or value != value:
        return NO_PRESSURE
    try:
        p = round(value)
    except (TypeError, ValueError, OverflowError):
        raise FrameError(f"{name}: expected a pressure [Pa] (a number or None), got {value!r}") from None
    if not -(2**31) <= p < NO_PRESSURE:
        raise FrameError(f"{name}: expected -2**31 <= p < 2**31-1 [Pa], got {value!r}")
    return p


def _is_lines(value) -> bool:
    return value is not None and not isinstance(value, (numbers.Real, str, bytes)) and hasattr(value, "__iter__")


def encode_sample(seq, t_us, adc, pressure_pa=None, status=0, tx_drops=0, pressures_pa=None) -> bytes:
    """Encode a SAMPLE as a whole wire frame.

    Parameters
    ----------
    seq : int
        Sequence number; taken modulo 65536 (the protocol wraps).
    t_us : int
        Device clock [us]; taken modulo 2**32.
    adc : sequence of int, length 1..64
        Raw counts, 0..65535.
    pressure_pa : float, None or sequence
        Pressure [Pa], rounded to an integer; None (or NaN) sends "no reading". With
        ``pressures_pa`` it may be left None (line 0 is sent) or must equal line 0. A
        sequence (tuple, list, array) is taken as ``pressures_pa``: a frame source that
        gives one pressure per line gets version 2 from any caller.
    status, tx_drops : int
        Status bits (0..255) and cumulative transmit drops (taken modulo 65536).
    pressures_pa : sequence of (float or None), length 1..255, optional
        One pressure [Pa] per pressure line: the frame is a version-2 SAMPLE
        (``n_lines``, ``pressure_pa[n_lines]`` after the ADC counts; offset 12 repeats
        line 0). None (default) sends version 1.

    Returns
    -------
    bytes
        ``0x00, COBS(body), 0x00``.
    """
    counts = [int(v) for v in adc]
    n = len(counts)
    if not 1 <= n <= MAX_CHANNELS:
        raise FrameError(f"adc: expected 1..{MAX_CHANNELS} channels, got {n}")
    if min(counts) < 0 or max(counts) > 0xFFFF:
        raise FrameError(f"adc: counts must be in 0..65535, got {min(counts)}..{max(counts)}")
    if pressures_pa is None and _is_lines(pressure_pa):
        pressure_pa, pressures_pa = None, pressure_pa
    p = _wire_pressure("pressure_pa", pressure_pa)
    status = _check_int("status", status, 0, 255)
    version, tail = VERSION, b""
    if pressures_pa is not None:
        lines = [_wire_pressure(f"pressures_pa[{k}]", v) for k, v in enumerate(pressures_pa)]
        if not 1 <= len(lines) <= MAX_LINES:
            raise FrameError(f"pressures_pa: expected 1..{MAX_LINES} pressure lines, got {len(lines)}")
        if pressure_pa is not None and p != lines[0]:
            raise FrameError(f"pressure_pa: {pressure_pa!r} differs from line 0 of pressures_pa ({pressures_pa[0]!r})")
        version, p = VERSION_LINES, lines[0]
        tail = struct.pack(f"<B{len(lines)}i", len(lines), *lines)
    payload = _SAMPLE_HEAD.pack(
        version, FrameType.SAMPLE, int(seq) & 0xFFFF, int(t_us) & 0xFFFFFFFF, n, status, int(tx_drops) & 0xFFFF, p
    ) + _adc_struct(n).pack(*counts)
    return frame_bytes(payload + tail)


def encode_hello(seq, t_us, n_channels, adc_bits, rate_hz, vref_mv, firmware="") -> bytes:
    """Encode a HELLO as a whole wire frame (``firmware``: ASCII, at most 32 bytes).

    Parameters
    ----------
    seq : int
        Sequence number (0..65535).
    t_us : int
        Device clock [µs] (0..2**32-1).
    n_channels : int
        Number of ADC channels (1..64).
    adc_bits : int
        ADC resolution [bits].
    rate_hz : int
        Frame rate [Hz].
    vref_mv : int
        ADC reference voltage [mV].
    firmware : str, default ""
        Firmware identifier, ASCII, at most 32 bytes.
    """
    fw = str(firmware).encode("ascii", errors="strict") if firmware else b""
    if len(fw) > MAX_FIRMWARE_BYTES:
        raise FrameError(f"firmware: at most {MAX_FIRMWARE_BYTES} ASCII bytes, got {len(fw)}")
    payload = _HELLO_HEAD.pack(
        VERSION,
        FrameType.HELLO,
        int(seq) & 0xFFFF,
        int(t_us) & 0xFFFFFFFF,
        _check_int("n_channels", n_channels, 1, MAX_CHANNELS),
        _check_int("adc_bits", adc_bits, 1, 16),
        _check_int("rate_hz", rate_hz, 0, 0xFFFF),
        _check_int("vref_mv", vref_mv, 0, 0xFFFF),
    )
    return frame_bytes(payload + fw)


def encode_text(seq, t_us, text: str) -> bytes:
    """Encode a TEXT (UTF-8 log line) as a whole wire frame.

    Parameters
    ----------
    seq : int
        Sequence number (0..65535).
    t_us : int
        Device clock [µs] (0..2**32-1).
    text : str
        The log line.
    """
    payload = _HEADER.pack(VERSION, FrameType.TEXT, int(seq) & 0xFFFF, int(t_us) & 0xFFFFFFFF)
    return frame_bytes(payload + str(text).encode("utf-8"))


_COMMANDS = (FrameType.START, FrameType.STOP, FrameType.HELLO_REQUEST, FrameType.HEARTBEAT)
_COMMAND_NAMES = {k.name.lower(): k for k in _COMMANDS}


def _command_kind(kind) -> FrameType:
    if isinstance(kind, str):
        k = _COMMAND_NAMES.get(kind.lower().replace("-", "_"))
        if k is not None:
            return k
    elif kind in _COMMANDS:
        return FrameType(kind)
    raise FrameError(f"command kind: expected one of {', '.join(map(repr, _COMMAND_NAMES))} "
                     f"(or {', '.join(str(int(k)) for k in _COMMANDS)}), got {kind!r}")


def encode_command(kind, seq: int = 0, t_us: int = 0) -> bytes:
    """Encode a host-to-device command (START, STOP, HELLO_REQUEST, HEARTBEAT) as a whole wire frame.

    The host has no sequence of its own that the device checks; the driver sends
    ``seq`` = a per-connection counter of commands and ``t_us`` = 0, both of which the
    firmware may ignore.

    Parameters
    ----------
    kind : FrameType, int or str
        ``START``, ``STOP``, ``HELLO_REQUEST`` or ``HEARTBEAT`` (or its name in lower case,
        e.g. ``"heartbeat"``).
    seq : int, default 0
        Sequence number (0..65535).
    t_us : int, default 0
        Host clock [µs]; the firmware may ignore it.
    """
    k = _command_kind(kind)
    return frame_bytes(_HEADER.pack(VERSION, k, int(seq) & 0xFFFF, int(t_us) & 0xFFFFFFFF))


def encode_setpoint(line, pressure_pa, seq: int = 0, t_us: int = 0) -> bytes:
    """Encode a SETPOINT (host to device: a pressure line's target) as a whole wire frame.

    Parameters
    ----------
    line : int
        Pressure line, 0-based (0..254).
    pressure_pa : float
        Target pressure [Pa], finite; rounded to an integer.
    seq : int, default 0
        Sequence number (0..65535, taken modulo 65536).
    t_us : int, default 0
        Host clock [µs] (taken modulo 2**32); the firmware may ignore it.

    Raises
    ------
    FrameError
        A line outside 0..254 or a pressure that is not a finite number within the i32 range.
    """
    if isinstance(line, bool) or not isinstance(line, numbers.Integral) or not 0 <= line < MAX_LINES:
        raise FrameError(f"line: expected a pressure line 0..{MAX_LINES - 1}, got {line!r}")
    if pressure_pa is None or not isinstance(pressure_pa, numbers.Real) or not math.isfinite(pressure_pa):
        raise FrameError(f"pressure_pa: expected a finite set-point [Pa], got {pressure_pa!r}")
    p = _wire_pressure("pressure_pa", pressure_pa)
    head = _HEADER.pack(VERSION, FrameType.SETPOINT, int(seq) & 0xFFFF, int(t_us) & 0xFFFFFFFF)
    return frame_bytes(head + _SETPOINT_TAIL.pack(int(line), p))


def encode_frame(frame) -> bytes:
    """Encode any frame object (:class:`Sample`, :class:`Hello`, :class:`Text`, :class:`Command`, :class:`Setpoint`).

    Parameters
    ----------
    frame : Sample, Hello, Text, Command or Setpoint
        The frame to encode (a Sample with ``pressures_pa`` as version 2).
    """
    if isinstance(frame, Sample):
        return encode_sample(frame.seq, frame.t_us or 0, frame.adc, frame.pressure_pa, frame.status, frame.tx_drops,
                             frame.pressures_pa or None)
    if isinstance(frame, Hello):
        return encode_hello(
            frame.seq, frame.t_us, frame.n_channels, frame.adc_bits, frame.rate_hz, frame.vref_mv, frame.firmware
        )
    if isinstance(frame, Text):
        return encode_text(frame.seq, frame.t_us, frame.text)
    if isinstance(frame, Command):
        return encode_command(frame.kind, frame.seq, frame.t_us)
    if isinstance(frame, Setpoint):
        return encode_setpoint(frame.line, frame.pressure_pa, frame.seq, frame.t_us)
    raise FrameError(f"frame: expected Sample, Hello, Text, Command or Setpoint, got {type(frame).__name__}")


# --------------------------------------------------------------------------- decoding

_CRC_ERROR = 1
_MALFORMED = 2


def _parse_body(body: bytes, adc_bits: int | None):
    """Frame object, or ``_CRC_ERROR`` / ``_MALFORMED``. Never raises."""
    n = len(body)
    if n < 10:  # 8-byte header + CRC
        return _MALFORMED
    if binascii.crc_hqx(body[:-2], 0xFFFF) != body[-2] | (body[-1] << 8):
        return _CRC_ERROR
    version = body[0]
    ftype = body[1]
    plen = n - 2
    if version != VERSION:
        return _parse_lines(body, adc_bits) if version == VERSION_LINES and ftype == 1 else _MALFORMED
    if ftype == 1:
        if plen < 18:
            return _MALFORMED
        nch = body[8]
        if not 1 <= nch <= MAX_CHANNELS or plen != 16 + 2 * nch:
            return _MALFORMED
        v = _sample_struct(nch).unpack_from(body)
        adc = v[8:]
        if adc_bits is not None and max(adc) >> adc_bits:
            return _MALFORMED
        p = v[7]
        return Sample(v[2], v[3], nch, v[5], v[6], None if p == NO_PRESSURE else p, adc)
    if ftype == 2:
        if not 14 <= plen <= 14 + MAX_FIRMWARE_BYTES:
            return _MALFORMED
        _, _, seq, t_us, nch, bits, rate, vref = _HELLO_HEAD.unpack_from(body)
        if not 1 <= nch <= MAX_CHANNELS or not 1 <= bits <= 16:
            return _MALFORMED
        fw = body[14:plen].decode("ascii", errors="replace")
        return Hello(seq, t_us, nch, bits, rate, vref, fw)
    if ftype == 3:
        _, _, seq, t_us = _HEADER.unpack_from(body)
        return Text(seq, t_us, body[8:plen].decode("utf-8", errors="replace"))
    if ftype in _COMMANDS:
        if plen != 8:
            return _MALFORMED
        _, _, seq, t_us = _HEADER.unpack_from(body)
        return Command(FrameType(ftype), seq, t_us)
    if ftype == 19:
        if plen != _SETPOINT.size:
            return _MALFORMED
        _, _, seq, t_us, line, p = _SETPOINT.unpack_from(body)
        if line >= MAX_LINES or p == NO_PRESSURE:
            return _MALFORMED
        return Setpoint(seq, t_us, line, p)
    return _MALFORMED


def _parse_lines(body: bytes, adc_bits: int | None):
    """A version-2 SAMPLE (CRC already checked), or ``_MALFORMED``. Never raises."""
    plen = len(body) - 2
    if plen < 16 + 2 + 1 + 4:
        return _MALFORMED
    nch = body[8]
    if not 1 <= nch <= MAX_CHANNELS or plen < 16 + 2 * nch + 1:
        return _MALFORMED
    n_lines = body[16 + 2 * nch]
    if not 1 <= n_lines <= MAX_LINES or plen != 16 + 2 * nch + 1 + 4 * n_lines:
        return _MALFORMED
    v = _sample_struct(nch).unpack_from(body)
    adc = v[8:]
    if adc_bits is not None and max(adc) >> adc_bits:
        return _MALFORMED
    lines = _lines_struct(n_lines).unpack_from(body, 17 + 2 * nch)
    p = v[7]
    if p != lines[0]:  # offset 12 repeats line 0: a frame that disagrees with itself is corrupt
        return _MALFORMED
    lines = tuple(None if x == NO_PRESSURE else x for x in lines)
    return Sample(v[2], v[3], nch, v[5], v[6], lines[0], adc, lines)


def decode_body(body: bytes, adc_bits: int | None = None):
    """Decode one un-stuffed body (payload + CRC) into a frame object.

    Parameters
    ----------
    body : bytes
        Un-stuffed body: payload followed by its CRC-16 (little-endian).
    adc_bits : int, optional
        ADC resolution [bits] from the device's HELLO; ADC values at or above
        ``2**adc_bits`` make the frame malformed. None skips that check.

    Raises
    ------
    FrameError
        On a CRC mismatch or a malformed payload.
    """
    frame = _parse_body(bytes(body), adc_bits)
    if frame is _CRC_ERROR:
        raise FrameError(f"CRC mismatch in a {len(body)}-byte body")
    if frame is _MALFORMED:
        raise FrameError(f"malformed {len(body)}-byte body (version, type, length or channel count)")
    return frame


def decode_frame(data: bytes, adc_bits: int | None = None):
    """Decode exactly one wire frame (delimiters optional); raises :class:`FrameError` if bad.

    Parameters
    ----------
    data : bytes
        One wire frame, with or without its ``0x00`` delimiters.
    adc_bits : int, optional
        ADC resolution [bits] (see :func:`decode_body`).
    """
    return decode_body(cobs_decode(bytes(data).strip(b"\x00")), adc_bits)


_HOST_FRAMES = (Command, Setpoint)


class Decoder(_StreamDecoder):
    """Incremental decoder of the binary protocol.

    Feed it bytes as they arrive, in chunks of any size; :meth:`feed` returns the
    complete frames found so far. It never raises on bad input: a segment between two
    ``0x00`` that fails COBS, the CRC or the payload checks is counted and skipped, and
    decoding resumes at the next delimiter. Empty segments (``0x00 0x00``) are normal.

    Parameters
    ----------
    adc_bits : int, optional
        ADC resolution; SAMPLE values at or above ``2**adc_bits`` are malformed. Taken
        from the first HELLO when not given.
    max_frame_bytes : int
        Longest run without a delimiter that is kept; a longer run is dropped (and
        counted in ``overruns`` and ``malformed``), so memory stays bounded. The default
        holds the longest legal frame (a version-2 SAMPLE of 64 channels and 255 lines,
        under 1,200 bytes stuffed).

    Attributes
    ----------
    frames : int
        Valid frames returned.
    crc_errors : int
        Segments whose CRC did not match.
    malformed : int
        Segments with bad COBS, bad length, unknown version or type, channel count
        outside 1..64, an ADC value out of range, a version-2 SAMPLE whose ``n_lines``
        is 0 or disagrees with its length or whose line 0 differs from offset 12, or a
        SETPOINT with a line above 254 or the no-reading pressure; includes over-long runs.
    overruns : int
        Over-long runs without a delimiter that were dropped.
    lost : int
        Frames missing from the device sequence: ``sum((seq - last - 1) mod 65536)``
        over consecutive valid device frames (SAMPLE, HELLO, TEXT; not the host's
        START, STOP, HELLO_REQUEST, SETPOINT, HEARTBEAT).
    bytes : int
        Bytes fed.
    hello : Hello or None
        The last HELLO seen.
    gaps : deque of (seq, n_lost)
        The most recent sequence gaps (bounded).
    """

    def __init__(self, adc_bits: int | None = None, max_frame_bytes: int = 2048):
        super().__init__()
        self.adc_bits = adc_bits
        self._adc_bits_from_hello = adc_bits is None
        self.max_frame_bytes = int(max_frame_bytes)

    def feed(self, data: bytes) -> list:
        """Decode ``data`` appended to what came before; return the complete frames in it.

        Parameters
        ----------
        data : bytes
            The next bytes of the stream, cut anywhere.
        """
        if not data:
            return []
        out = []
        append = out.append
        for seg in self._segments(bytes(data), b"\x00", self.max_frame_bytes):
            body = _cobs_decode(seg)
            if body is None:
                self.malformed += 1
                continue
            frame = _parse_body(body, self.adc_bits)
            if frame is _CRC_ERROR:
                self.crc_errors += 1
                continue
            if frame is _MALFORMED:
                self.malformed += 1
                continue
            self.frames += 1
            if type(frame) not in _HOST_FRAMES:
                self._count_sequence(frame.seq)
                if type(frame) is Hello:
                    self.hello = frame
                    if self._adc_bits_from_hello:
                        self.adc_bits = frame.adc_bits
            append(frame)
        return out


class LineDecoder(_StreamDecoder):
    """Incremental decoder of the line dialect: one frame per line, for simple firmware.

    Numbers are separated by commas or whitespace; a line starting with ``#`` is a
    comment; a line equal to the column names is a header and skipped. Any other line
    that does not parse is counted in ``malformed`` and skipped.

    Parameters
    ----------
    columns : sequence of str, optional
        Column layout. Channel columns are ``ch1..chN`` (in any order); optional
        ``seq``, ``t_us`` and ``pressure_pa`` (``nan`` = no reading); any other name is
        read and ignored. Default: ``ch1..ch{n_channels}``.
    n_channels : int, optional
        Number of channels for the default layout.
    max_line_bytes : int
        Longest line kept; a longer one is dropped and counted (bounded memory).

    Attributes
    ----------
    frames, malformed, lost, overruns : int
        As in :class:`Decoder`; without a ``seq`` column the decoder numbers the lines
        itself and ``lost`` stays 0.
    """

    def __init__(self, columns=None, n_channels: int | None = None, max_line_bytes: int = 4096):
        if columns is None:
            if n_channels is None:
                raise FrameError("the line dialect needs its column layout: give columns (e.g. seq,t_us,ch1,...) "
                                 "or n_channels")
            columns = [f"ch{i + 1}" for i in range(_check_int("n_channels", n_channels, 1, MAX_CHANNELS))]
        columns = [str(c).strip() for c in columns]
        chans = {}
        for i, c in enumerate(columns):
            if c.startswith("ch") and c[2:].isdigit() and int(c[2:]) >= 1:
                chans[int(c[2:])] = i
        if not chans or sorted(chans) != list(range(1, len(chans) + 1)):
            raise FrameError(f"columns: expected ch1..chN among the columns, got {columns}")
        if len(set(columns)) != len(columns):
            raise FrameError(f"columns: duplicate names in {columns}")
        super().__init__()
        self.columns = tuple(columns)
        self.n_channels = len(chans)
        self._chan_idx = [chans[k] for k in range(1, len(chans) + 1)]
        self._seq_idx = columns.index("seq") if "seq" in columns else None
        self._t_idx = columns.index("t_us") if "t_us" in columns else None
        self._p_idx = columns.index("pressure_pa") if "pressure_pa" in columns else None
        self.max_line_bytes = int(max_line_bytes)
        self._count = 0
        self.adc_bits = None  # crc_errors stays 0: no CRC in this dialect (uniform stats)

    def feed(self, data) -> list:
        """Decode ``data`` (bytes or str) appended to what came before; return complete frames.

        Parameters
        ----------
        data : bytes or str
            The next characters of the stream, cut anywhere.
        """
        if not data:
            return []
        if isinstance(data, str):
            data = data.encode("utf-8")
        out = []
        for raw in self._segments(bytes(data).replace(b"\r", b"\n"), b"\n", self.max_line_bytes):
            frame = self._parse_line(raw)
            if frame is not None:
                out.append(frame)
        return out

    def _parse_line(self, raw: bytes):
        try:
            line = raw.decode("utf-8").strip()
        except UnicodeDecodeError:
            self.malformed += 1
            return None
        if not line or line.startswith("#"):
            return None
        tokens = line.replace(",", " ").split()
        if tuple(tokens) == self.columns:
            return None
        if len(tokens) != len(self.columns):
            self.malformed += 1
            return None
        try:
            values = [float(t) for t in tokens]
        except ValueError:
            self.malformed += 1
            return None
        adc = tuple(_int_if_integral(values[i]) for i in self._chan_idx)
        if any(v != v or v in (float("inf"), float("-inf")) for v in adc):
            self.malformed += 1
            return None
        seq = None
        if self._seq_idx is not None:
            s = values[self._seq_idx]
            if s != s or s in (float("inf"), float("-inf")) or s != int(s) or s < 0:
                self.malformed += 1
                return None
            seq = int(s) & 0xFFFF
        t_us = None
        if self._t_idx is not None:
            t = values[self._t_idx]
            if t != t or t < 0 or t == float("inf"):
                self.malformed += 1
                return None
            t_us = int(round(t)) & 0xFFFFFFFF
        p = None
        if self._p_idx is not None:
            pv = values[self._p_idx]
            p = None if pv != pv else _int_if_integral(pv)
        if seq is None:
            seq = self._count & 0xFFFF
        else:
            self._count_sequence(seq)
        self._count += 1
        self.frames += 1
        return Sample(seq, t_us, self.n_channels, 0, 0, p, adc)


def _int_if_integral(v: float):
    if v == v and abs(v) < 2**53 and v == int(v):
        return int(v)
    return v
