"""Driver and several pressure lines: v2 readings and SETPOINTs over a real pseudo-terminal.

The device side here is the pseudo-terminal's master end, written and read by the test
itself (hand-encoded frames out, a stream Decoder on what the host sends), so what is
checked is the bytes that reach a board.
"""

import math
import os
import threading
import time
import tty

import pytest

from bendsense.device import Driver
from bendsense.errors import ArgumentError, DeviceError
from bendsense.wire.frames import Decoder, Setpoint, encode_sample

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs POSIX pseudo-terminals")


class Board:
    """The device end of a pseudo-terminal: writes frames, decodes what the host writes."""

    def __init__(self):
        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.port = os.ttyname(slave)
        self._slave = slave
        self.decoder = Decoder()

    def send(self, data: bytes) -> None:
        os.write(self.master, data)

    def received(self, n_frames: int, timeout: float = 5.0) -> list:
        out = []
        end = time.monotonic() + timeout
        os.set_blocking(self.master, False)
        while len(out) < n_frames and time.monotonic() < end:
            try:
                out += self.decoder.feed(os.read(self.master, 65536))
            except BlockingIOError:
                time.sleep(0.005)
        return out

    def close(self):
        os.close(self.master)
        os.close(self._slave)


@pytest.fixture
def board():
    b = Board()
    yield b
    b.close()


def test_readings_of_v2_frames_carry_the_lines_and_setpoints_reach_the_board(board):
    with Driver(board.port, handshake=False) as drv:
        board.send(b"".join(encode_sample(k, 1000 * k, [k, 2 * k], pressures_pa=[50_000 + k, None, 30_000 - k])
                            for k in range(3)))
        got = [drv.get(timeout=5) for _ in range(3)]
        assert [r.sample.pressures_pa for r in got] == [(50_000 + k, None, 30_000 - k) for k in range(3)]
        assert [r.sample.pressure_pa for r in got] == [50_000, 50_001, 50_002]
        drv.send_setpoint(2, 45_000.4)
        drv.send_setpoint(0, 0)
        drv.send_setpoint(1, 119_999.6)
        frames = board.received(3)
    assert [(f.line, f.pressure_pa) for f in frames] == [(2, 45_000), (0, 0), (1, 120_000)]
    assert all(type(f) is Setpoint for f in frames) and board.decoder.errors == 0


def test_send_setpoints_sends_a_blocks_lines_together_or_none(board):
    """A loop's set-points of one block: every line's SETPOINT, each with its own sequence number, in one write;
    a refused line or pressure among them sends none of them."""
    with Driver(board.port, handshake=False) as drv:
        board.send(encode_sample(0, 0, [1], pressures_pa=[1, 2, 3]))
        assert drv.get(timeout=5) is not None
        writes = []
        write = drv.write
        drv.write = lambda data, drain=True: writes.append(data) or write(data, drain=drain)
        drv.send_setpoints({2: 45_000.4, 0: 0.0, 1: 119_999.6})
        for bad, match in (({0: 10.0, 1: math.nan}, "pressure_pa"), ({0: 10.0, 3: 5.0}, "line: 3 is not a pressure")):
            with pytest.raises(ArgumentError, match=match):
                drv.send_setpoints(bad)
        drv.send_setpoints({})  # nothing to send: nothing written
        drains = []
        flush = drv._ser.flush
        drv._ser.flush = lambda: drains.append(len(writes)) or flush()
        drv.send_setpoints({1: 7}, drain=False)  # a loop's block: the system sends the bytes on by itself
        drv.send_setpoint(0, 0.0)  # a zero: back once it has left the host
        frames = board.received(5)
    assert [(f.line, f.pressure_pa) for f in frames] == [(2, 45_000), (0, 0), (1, 120_000), (1, 7), (0, 0)]
    assert len(writes) == 3 and drains == [3] and board.decoder.errors == 0
    assert len({f.seq for f in frames}) == 5 and [f.seq for f in frames[:3]] == sorted(f.seq for f in frames[:3])


def test_send_setpoint_from_several_threads_keeps_frames_whole(board):
    with Driver(board.port, handshake=False) as drv:
        def send(line):
            for k in range(40):
                drv.send_setpoint(line, 1000 * line + k)
                drv.send_heartbeat()

        threads = [threading.Thread(target=send, args=(line,)) for line in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        frames = board.received(320)
    assert board.decoder.errors == 0 and len(frames) == 320
    setpoints = [f for f in frames if type(f) is Setpoint]
    for line in range(4):  # each thread's set-points arrive whole and in its order
        assert [f.pressure_pa for f in setpoints if f.line == line] == [1000 * line + k for k in range(40)]
    assert sorted(f.seq for f in frames) == list(range(1, 321))  # every frame its own sequence number


@pytest.mark.parametrize(
    "line, p, match",
    [
        (0, math.nan, r"pressure_pa: expected a finite set-point \[Pa\], got nan"),
        (0, -math.inf, r"pressure_pa: expected a finite set-point \[Pa\], got -inf"),
        (0, 3e9, r"pressure_pa: expected -2\*\*31 <= p < 2\*\*31-1 \[Pa\], got 3000000000.0"),
        (0, "5", r"pressure_pa: expected a finite set-point \[Pa\], got '5'"),
        (-1, 0, r"line: expected a pressure line 0..254, got -1"),
        (255, 0, r"line: expected a pressure line 0..254, got 255"),
        (1.0, 0, r"line: expected a pressure line 0..254, got 1.0"),
        (2, 0, r"line: 2 is not a pressure line of the board on .* \(it sends 2 lines, 0..1\)"),
    ],
)
def test_send_setpoint_refuses_bad_values_and_sends_nothing(board, line, p, match):
    with Driver(board.port, handshake=False) as drv:
        board.send(encode_sample(0, 0, [1], pressures_pa=[1, 2]))
        assert drv.get(timeout=5) is not None
        with pytest.raises(ArgumentError, match=match):
            drv.send_setpoint(line, p)
        drv.send_setpoint(1, 7)  # the next good one is the first the board gets
        frames = board.received(1)
    assert [(f.line, f.pressure_pa) for f in frames] == [(1, 7)] and board.decoder.errors == 0


def test_send_setpoint_on_a_closed_port_or_the_line_dialect(board):
    drv = Driver(board.port, handshake=False)
    with pytest.raises(DeviceError, match="not open"):
        drv.send_setpoint(0, 1000)
    drv.open()
    board.send(encode_sample(0, 0, [1], pressure_pa=5))  # a version-1 board: line 0 only
    assert drv.get(timeout=5).sample.pressures_pa == ()
    with pytest.raises(ArgumentError, match=r"line: 1 is not a pressure line .* \(it sends 1 line, 0..0\)"):
        drv.send_setpoint(1, 1000)
    drv.close()
    with pytest.raises(DeviceError, match="not open"):
        drv.send_setpoint(0, 1000)
    with Driver(board.port, dialect="line", n_channels=1) as line_drv, \
            pytest.raises(DeviceError, match="the line dialect has no set-points"):
        line_drv.send_setpoint(0, 1000)


def test_bad_v2_frames_are_counted_and_the_good_ones_read(board):
    import binascii
    import struct

    from bendsense.wire.frames import cobs_encode

    def wire(payload):
        return b"\x00" + cobs_encode(payload + struct.pack("<H", binascii.crc_hqx(payload, 0xFFFF))) + b"\x00"

    head = struct.pack("<BBHIBBHi", 2, 1, 5, 0, 1, 0, 0, 1000) + struct.pack("<H", 7)
    bad = [wire(head + struct.pack("<B2i", 3, 1000, 2000)),  # n_lines says 3, the payload holds 2
           wire(head + struct.pack("<B2i", 2, 1000, 2000)[:-2]),  # truncated in the last line
           wire(head + struct.pack("<B2i", 2, 999, 2000))]  # line 0 is not offset 12
    with Driver(board.port, handshake=False) as drv:
        board.send(b"".join(bad) + encode_sample(6, 0, [8], pressures_pa=[1000, 2000]))
        got = drv.get(timeout=5)
        assert got.sample.seq == 6 and got.sample.pressures_pa == (1000, 2000)
        deadline = time.monotonic() + 5
        while not any(e.kind == "malformed" for e in drv.events):
            assert time.monotonic() < deadline, "timed out"
            time.sleep(0.01)
        assert drv.stats.malformed == 3 and drv.stats.samples == 1


def test_a_write_beyond_the_ports_buffer_waits_and_arrives_whole(board):
    """The driver writes with one system call; what the port's buffer does not take goes through pyserial's write,
    which waits for the board to read (here a board that starts reading 0.2 s late): every frame, in order."""
    from bendsense.wire.frames import encode_setpoint

    setpoints = [(k % 4, 1000 * k) for k in range(6000)]  # ~100 kB, beyond what a pseudo-terminal holds
    data = b"".join(encode_setpoint(line, p, seq=seq) for seq, (line, p) in enumerate(setpoints))
    with Driver(board.port, handshake=False) as drv:
        rest = []
        write = drv._ser.write
        drv._ser.write = lambda d: rest.append(len(d)) or write(d)
        writer = threading.Thread(target=drv.write, args=(data,))
        writer.start()
        time.sleep(0.2)
        frames = board.received(len(setpoints), timeout=20)
        writer.join(5)
    assert not writer.is_alive() and board.decoder.errors == 0
    assert [(f.line, f.pressure_pa) for f in frames] == setpoints
    assert len(rest) == 1 and 0 < rest[0] < len(data)  # the system call took a part, pyserial's write the rest


def test_a_write_to_a_board_that_is_gone_is_a_device_error(board):
    with Driver(board.port, handshake=False) as drv:
        board.close()
        board.close = lambda: None
        with pytest.raises(DeviceError, match="write failed"):
            for _ in range(100):  # the reader may notice first and reconnect; the write then fails on its own
                drv.send_setpoint(0, 1000.0, check_line=False)
                time.sleep(0.01)
