"""Framing layer of the wire protocol: CRC-16/CCITT-FALSE and COBS (DESIGN.md section 3).

Each frame on the wire is ``0x00, COBS(body), 0x00`` with ``body = payload + CRC16``
(CRC-16/CCITT-FALSE of the payload, little-endian). Pure functions, no IO; the payloads
and the stream decoders are :mod:`bendsense.wire.frames`, which re-exports these names; their
shared stream bookkeeping (delimiter splitting, bounded buffer, counters, sequence gaps)
is :class:`_StreamDecoder` here.
"""

from __future__ import annotations

import binascii
from collections import deque

from bendsense.errors import FrameError

__all__ = ["crc16_ccitt_false", "cobs_encode", "cobs_decode", "frame_bytes"]




def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final xor).

    The check value, ``crc16_ccitt_false(b"123456789")``, is 0x29B1.

    Parameters
    ----------
    data : bytes
        The bytes to check (a frame's payload).
    """
    return binascii.crc_hqx(data, 0xFFFF)


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: ``data`` without any zero byte, overhead 1 + len/254.

    Parameters
    ----------
    data : bytes
        The bytes to stuff.
    """
    out = bytearray()
    for part in bytes(data).split(b"\x00"):
        while len(part) >= 254:
            out.append(0xFF)
            out += part[:254]
            part = part[254:]
        out.append(len(part) + 1)
        out += part
    return bytes(out)


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`.

    Parameters
    ----------
    data : bytes
        Stuffed bytes, without delimiters.

    Raises
    ------
    FrameError
        If ``data`` contains a zero byte or a block runs past its end.
    """
    data = bytes(data)
    out = None if 0 in data else _cobs_decode(data)
    if out is None:
        raise FrameError(f"COBS: invalid encoding of {len(data)} bytes (zero byte or block past the end)")
    return out


def _cobs_decode(data: bytes) -> bytes | None:
    # Hot path, called on segments already split at 0x00: no exceptions, None if invalid.
    # Every block but the last is followed by a zero, so joining the blocks with b"\x00"
    # decodes; 0xFF blocks (runs of 254 non-zero bytes, rare) take the general loop.
    n = len(data)
    parts = []
    i = 0
    while i < n:
        code = data[i]
        if code == 0xFF:
            return _cobs_decode_general(data)
        end = i + code
        if end > n or code == 0:
            return None
        parts.append(data[i + 1 : end])
        i = end
    return b"\x00".join(parts) if parts else None


def _cobs_decode_general(data: bytes) -> bytes | None:
    n = len(data)
    if n == 0 or 0 in data:
        return None
    out = bytearray()
    i = 0
    while i < n:
        code = data[i]
        end = i + code
        if end > n:
            return None
        out += data[i + 1 : end]
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)


def frame_bytes(payload: bytes) -> bytes:
    """Wire frame of ``payload``: ``0x00, COBS(payload + CRC16 LE), 0x00``.

    Parameters
    ----------
    payload : bytes
        The frame's payload (DESIGN.md section 3).
    """
    body = payload + crc16_ccitt_false(payload).to_bytes(2, "little")
    return b"\x00" + cobs_encode(body) + b"\x00"


class _StreamDecoder:
    """Counters, bounded segment buffer and sequence-gap accounting of both decoders.

    Subclasses split their stream with :meth:`_segments` and parse each segment.
    """

    def __init__(self):
        self._buf = b""
        self._discarding = False
        self._last_seq = None
        self.frames = 0
        self.crc_errors = 0
        self.malformed = 0
        self.overruns = 0
        self.lost = 0
        self.bytes = 0
        self.hello = None
        self.gaps = deque(maxlen=1000)

    @property
    def errors(self) -> int:
        """``crc_errors + malformed``."""
        return self.crc_errors + self.malformed

    def reset(self) -> None:
        """Forget a partial frame (e.g. after a reconnect); counters and sequence are kept."""
        self._buf = b""
        self._discarding = False

    def reset_sequence(self) -> None:
        """Forget the last sequence number (the next frame starts a new sequence)."""
        self._last_seq = None

    def _segments(self, data: bytes, delimiter: bytes, max_bytes: int) -> list:
        """The complete, non-empty segments that ``data`` ends, after what came before.

        The incomplete tail is kept for the next call. A segment (or a run without a
        delimiter) longer than ``max_bytes`` is dropped and counted in ``overruns`` and
        ``malformed``, so memory stays bounded.
        """
        self.bytes += len(data)
        if delimiter not in data:
            if not self._discarding:
                self._buf += data
                if len(self._buf) > max_bytes:
                    self._overrun()
            return []
        parts = data.split(delimiter)
        tail = parts.pop()
        if self._discarding:
            parts[0] = b""  # the end of an over-long run
            self._discarding = False
        elif self._buf:
            parts[0] = self._buf + parts[0]
        self._buf = tail
        if len(tail) > max_bytes:
            self._overrun()
        segments = []
        for seg in parts:
            if len(seg) > max_bytes:
                self.overruns += 1
                self.malformed += 1
            elif seg:
                segments.append(seg)
        return segments

    def _overrun(self) -> None:
        self._buf = b""
        self._discarding = True
        self.overruns += 1
        self.malformed += 1

    def _count_sequence(self, seq: int) -> None:
        """Add the frames missing between the last sequence number and ``seq`` to ``lost``."""
        last = self._last_seq
        if last is not None:
            gap = (seq - last - 1) & 0xFFFF
            if gap:
                self.lost += gap
                self.gaps.append((seq, gap))
        self._last_seq = seq
