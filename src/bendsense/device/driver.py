"""Serial driver of the sensor board: reader thread, frame queue, live value, reconnects.

The driver opens any pyserial port or URL (``/dev/ttyACM0``, ``COM3``, a pseudo-terminal
path such as ``/dev/pts/5``, ``loop://``), reads in bulk on a background thread, decodes
with :class:`bendsense.wire.frames.Decoder` (or :class:`~bendsense.wire.frames.LineDecoder`) and
hands every SAMPLE on to two consumers:

- a bounded queue for the recorder, which never drops silently: when it is full the
  reader blocks briefly, then counts ``queue_drops`` and logs an event;
- a lossy latest-value slot for the live view (:meth:`Driver.latest`).

A loop that acts on each frame as it comes (:func:`bendsense.control.run`) reads the port
in its own thread instead (:meth:`Driver.reading_here`): a frame then reaches it without
waiting for the reader thread's turn at the GIL.

Read errors (port vanished, pseudo-terminal closed) trigger bounded reconnect attempts
with exponential backoff; if they fail, or the driver is closed, consumers blocked in
:meth:`Driver.get` or iterating get a :class:`~bendsense.errors.DeviceError` instead of
hanging.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import numbers
import os
import queue
import re
import select
import threading
import time
from collections import deque
from dataclasses import dataclass

from bendsense.errors import ArgumentError, DeviceError, FrameError
from bendsense.wire.frames import (
    MAX_LINES,
    Command,
    Decoder,
    FrameType,
    Hello,
    LineDecoder,
    Sample,
    Setpoint,
    Text,
    encode_command,
    encode_setpoint,
)

__all__ = ["Reading", "Event", "DeviceStats", "Driver", "Reconnect", "DEFAULT_BAUDRATE"]

log = logging.getLogger("bendsense.device")

DEFAULT_BAUDRATE = 921_600
BAUD_RANGE = (50, 12_000_000)
"""Baud rates a serial port can be opened at: the slowest standard rate to the fastest USB-serial bridges (FT232H)."""
"""Default baud rate; 16 channels at 1 kHz need ~0.5 Mbit/s (USB CDC ignores it)."""


@dataclass(frozen=True, slots=True)
class Reading:
    """A SAMPLE as received.

    Attributes
    ----------
    host_ns : int
        Host clock, ``time.monotonic_ns()`` when its bytes were read [ns].
    device_us : int
        Device clock with the u32 wraps removed [us] (the host clock in us since the
        first frame when the line dialect carries no ``t_us``).
    sample : Sample
        The decoded frame (raw ``seq`` and ``t_us``).
    """

    host_ns: int
    device_us: int
    sample: Sample


@dataclass(frozen=True, slots=True)
class Event:
    """Something worth a line in ``events.log``.

    ``kind`` is one of ``hello``, ``text``, ``gap``, ``crc``, ``malformed``, ``overrun``,
    ``queue_drop``, ``clock``, ``disconnect``, ``reconnect``, ``error``, ``info``.
    """

    time_s: float
    kind: str
    text: str


@dataclass(frozen=True, kw_only=True)
class Reconnect:
    """How a :class:`Driver` tries to get a vanished port back after a read error.

    Attempt ``i`` (1-based) waits ``min(backoff_s * 2**(i - 1), 2 s)`` first, then opens
    the port again (and repeats the HELLO_REQUEST and START it had sent).

    Attributes
    ----------
    attempts : int
        Reconnect attempts before giving up (0: none).
    backoff_s : float
        Delay before the first attempt; doubles each attempt, at most 2 s [s].
    """

    attempts: int = 5
    backoff_s: float = 0.1

    def __post_init__(self):
        if isinstance(self.attempts, bool) or not isinstance(self.attempts, numbers.Integral) or self.attempts < 0:
            raise DeviceError(f"reconnect.attempts: expected an integer >= 0, got {self.attempts!r}")
        if isinstance(self.backoff_s, bool) or not isinstance(self.backoff_s, numbers.Real) \
                or not 0 <= self.backoff_s < float("inf"):
            raise DeviceError(f"reconnect.backoff_s: expected a time >= 0 [s], got {self.backoff_s!r}")


@dataclass(frozen=True)
class DeviceStats:
    """Counters of a driver (a snapshot)."""

    frames: int
    samples: int
    crc_errors: int
    malformed: int
    lost: int
    queue_drops: int
    reconnects: int
    overruns: int
    bytes: int


class Driver:
    """Sensor board on a serial port.

    Parameters
    ----------
    port : str
        Port name, pseudo-terminal path or pyserial URL (``loop://``, ``socket://``...).
    baudrate : int
        Baud rate (ignored by USB CDC and pseudo-terminals).
    dialect : {"binary", "line"}
        Wire protocol (DESIGN.md section 3).
    columns : sequence of str, optional
        Line-dialect column layout (default ``ch1..chN`` with ``n_channels``).
    n_channels : int, optional
        Line-dialect channel count for the default layout.
    handshake : bool
        Binary dialect: on :meth:`open`, send HELLO_REQUEST and wait for HELLO.
    hello_timeout_s : float
        How long to wait for the HELLO [s].
    queue_size : int or None
        Capacity of the recorder queue [readings]; None: no queue (live value only).
    queue_block_s : float
        How long the reader blocks on a full queue before it counts a drop [s].
    reconnect : Reconnect, optional
        Reconnect attempts and their backoff after a read error; default ``Reconnect()``
        (5 attempts from 0.1 s).

    Attributes
    ----------
    read_timeout_s : float
        Serial read timeout (0.02 s); bounds how fast the reader notices :meth:`close` [s].
    here_stall_s : float
        While the caller reads the port (:meth:`reading_here`): how long it may stay away
        from :meth:`get_batch` before the reader thread reads for it (0.1 s), so that a
        caller held up for seconds loses no frame to a full port [s].

    Examples
    --------
    >>> with Driver("/dev/ttyACM0") as dev:          # doctest: +SKIP
    ...     dev.start()
    ...     for reading in dev:
    ...         print(reading.sample.adc)
    """

    read_timeout_s = 0.02
    here_stall_s = 0.1

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = DEFAULT_BAUDRATE,
        dialect: str = "binary",
        columns=None,
        n_channels: int | None = None,
        handshake: bool = True,
        hello_timeout_s: float = 2.0,
        queue_size: int | None = 10_000,
        queue_block_s: float = 0.05,
        reconnect: Reconnect | None = None,
    ):
        if dialect not in ("binary", "line"):
            raise DeviceError(f"dialect: expected 'binary' or 'line', got {dialect!r}")
        if queue_size is not None and queue_size < 1:
            raise DeviceError(f"queue_size: expected a positive integer or None, got {queue_size!r}")
        lo, hi = BAUD_RANGE
        if isinstance(baudrate, bool) or not isinstance(baudrate, numbers.Integral) or not lo <= baudrate <= hi:
            raise DeviceError(f"baudrate: expected an integer in {lo}..{hi:,} (serial baud rates), got {baudrate!r}")
        self.port = str(port)
        self.baudrate = int(baudrate)
        self.dialect = dialect
        self.handshake = bool(handshake) and dialect == "binary"
        self.hello_timeout_s = float(hello_timeout_s)
        self.queue_block_s = float(queue_block_s)
        if reconnect is not None and not isinstance(reconnect, Reconnect):
            raise DeviceError(f"reconnect: expected a Reconnect, got {type(reconnect).__name__}")
        self.reconnect = Reconnect() if reconnect is None else reconnect
        if dialect == "binary":
            self.decoder = Decoder()
        else:
            self.decoder = LineDecoder(columns=columns, n_channels=n_channels)
        # SimpleQueue: its locks are C's, which a Ctrl-C cannot leave held (queue.Queue's Python-level
        # Condition can: raised inside its __enter__, the lock stays taken and the next get waits for ever)
        self._queue = None if queue_size is None else queue.SimpleQueue()
        self._queue_size = None if queue_size is None else int(queue_size)
        self._ser = None
        self._thread = None
        self._write_lock = threading.Lock()
        # who reads the port, by two flags and no lock (a Ctrl-C can skip a Python-level release, never a flag's
        # reset at the next read): each sets its own, then backs off while the other's is set (_read_here, _run)
        self._reading_here = False  # the caller's thread reads the port (reading_here)
        self._caller_in = False  # the caller is reading or decoding (reading_here)
        self._thread_in = False  # the reader thread is reading or decoding
        self._here_at = 0.0  # when the caller last waited on the port (time.monotonic())
        self._pending = []  # readings taken from the port or the queue by reading_here, served before the queue
        self._closing = threading.Event()
        self._hello_event = threading.Event()
        self._listeners = []
        self.events = deque(maxlen=1000)
        self._error: str | None = None
        self._closed = False
        self._streaming = False
        self._cmd_seq = 0
        self._latest = None
        self._samples = 0
        self._queue_drops = 0
        self._reconnects = 0
        self._last_t = None
        self._device_us = 0
        self._first_host_ns = None
        self._seen = (0, 0, 0)

    # ------------------------------------------------------------------ lifecycle

    def _open_serial(self):
        import serial

        # exclusive: a second bendsense on the port is refused (it would take half of each other's bytes)
        kwargs = {"baudrate": self.baudrate, "timeout": self.read_timeout_s, "exclusive": True}
        try:
            try:
                return serial.serial_for_url(self.port, write_timeout=1.0, **kwargs)
            except NotImplementedError:
                # some URL handlers (rfc2217://) cannot bound writes; open them without
                return serial.serial_for_url(self.port, **kwargs)
        except (serial.SerialException, OSError, ValueError, NotImplementedError) as err:
            if getattr(err, "errno", None) != errno.EACCES:  # denied: that is the message, whatever the path is
                _check_port_path(self.port)  # a directory or a regular file: say so, not pyserial's ioctl error
            text = " ".join(str(err).split())[:200]
            if "exclusively lock" in text:
                raise DeviceError(f"{self.port}: in use by another program that reads it (another bendsense record, "
                                  "live or control?); one program at a time reads a board") from None
            if f"({errno.ENOTTY}," in text or getattr(err, "errno", None) == errno.ENOTTY:
                raise DeviceError(f"{self.port}: a device that is no terminal, not a serial port (give the board's "
                                  "port, e.g. /dev/ttyACM0; 'bendsense devices' lists them)") from None
            raise DeviceError(f"{self.port}: cannot open serial port ({text})") from None

    def open(self) -> Driver:
        """Open the port, start the reader and (binary dialect) do the HELLO handshake.

        Raises
        ------
        DeviceError
            If the port cannot be opened or no HELLO arrives within ``hello_timeout_s``.
        """
        if self._thread is not None:
            return self
        self._ser = self._open_serial()
        self._thread = threading.Thread(target=self._run, name=f"bendsense-reader {self.port}", daemon=True)
        self._thread.start()
        if self.handshake:
            try:
                self.request_hello(timeout_s=self.hello_timeout_s)
            except DeviceError:
                self.close()
                raise
        return self

    def request_hello(self, timeout_s: float = 2.0) -> Hello:
        """Send HELLO_REQUEST (re-sent every 0.5 s) and wait for the HELLO.

        Parameters
        ----------
        timeout_s : float, default 2.0
            Longest wait for the HELLO [s].
        """
        self._hello_event.clear()
        deadline = time.monotonic() + timeout_s
        while True:
            self.send("hello_request")
            left = deadline - time.monotonic()
            if self._hello_event.wait(min(0.5, max(left, 0.0))):
                return self.hello
            if self._error is not None:
                raise DeviceError(self._error)
            if time.monotonic() >= deadline:
                raise DeviceError(
                    f"{self.port}: no HELLO within {timeout_s:g} s after HELLO_REQUEST "
                    f"(is it a bendsense board speaking the binary protocol at {self.baudrate} baud?)"
                )

    def close(self) -> None:
        """Send STOP if streaming, stop the reader and close the port (idempotent)."""
        if self._closed:
            return
        if self._streaming and self._error is None:
            try:
                self.stop()
            except DeviceError:
                pass
        self._closed = True
        self._closing.set()
        ser = self._ser
        if ser is not None and hasattr(ser, "cancel_read"):
            try:
                ser.cancel_read()
            except Exception:  # noqa: BLE001 - the port may already be gone
                pass
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: BLE001
                pass

    def __enter__(self) -> Driver:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ commands

    def write(self, data: bytes, *, drain: bool = True) -> None:
        """Write raw bytes to the port.

        Parameters
        ----------
        data : bytes
            The bytes to write.
        drain : bool, default True
            Return once the bytes have left the host (the port's output drained), not once
            they are in the system's buffer (which sends them on by itself).
        """
        if self._closed or self._ser is None:
            raise DeviceError(f"{self.port}: not open")
        try:
            with self._write_lock:
                ser = self._ser
                done, fd = 0, getattr(ser, "fd", None)  # a POSIX port's descriptor (pyserial's serialposix)
                if fd is not None:  # one system call, not pyserial's write and the select after it (~15 µs)
                    try:
                        done = os.write(fd, data)
                    except BlockingIOError:  # the port's buffer is full: pyserial's write waits, up to its timeout
                        pass
                if done < len(data):
                    ser.write(data[done:])
                if drain:
                    ser.flush()
        except Exception as err:  # noqa: BLE001 - pyserial raises several types here
            # a port closed under us is the reader's: its read failed, it reconnects (pyserial: "not open")
            reason = "the port is closed: its last read failed" if not getattr(self._ser, "is_open", True) else \
                _os_reason(err)
            raise DeviceError(f"{self.port}: write failed ({reason})") from None

    def send(self, kind: str) -> None:
        """Send a command: ``"start"``, ``"stop"`` or ``"hello_request"`` (binary dialect only).

        Parameters
        ----------
        kind : str
            ``"start"``, ``"stop"`` or ``"hello_request"``.
        """
        if self.dialect != "binary":
            return
        self.write(encode_command(kind, seq=self._next_command_seq()))

    def send_setpoint(self, line: int, pressure_pa: float, *, check_line: bool = True) -> None:
        """Send a SETPOINT: the target pressure of one of the board's pressure lines.

        Thread-safe (writes are serialised with the commands). The pressure is rounded
        to a whole pascal. Once the board has sent a SAMPLE, ``line`` must be one of its
        lines (``len(sample.pressures_pa)``, or line 0 of a version-1 board), unless
        ``check_line`` is False.

        Parameters
        ----------
        line : int
            Pressure line, 0-based (0..254).
        pressure_pa : float
            Target pressure [Pa]: a finite number below 2**31 - 1 in magnitude.
        check_line : bool, default True
            Refuse a line the board's latest SAMPLE does not carry. The control loop
            sends without this check: a line the board stopped reporting may still be
            pressurised, and letting it go must not depend on the board's reports.

        Raises
        ------
        ArgumentError
            A line that is not an integer in range, or (``check_line``) not a line the
            board has; a pressure that is not finite or beyond the wire's range.
        DeviceError
            The port is closed (or was never opened), the write fails, or the driver
            speaks the line dialect (which has no host-to-device frames).
        """
        self.send_setpoints({line: pressure_pa}, check_line=check_line)

    def send_setpoints(self, setpoints, *, check_line: bool = True, drain: bool = True) -> None:
        """Send a SETPOINT for each line of ``setpoints`` (line → pressure [Pa]), in one write.

        :meth:`send_setpoint` of each, checked first: a line or pressure refused sends
        none. One write for all of them: a gripper's loop sends its fingers' set-points
        together.

        Parameters
        ----------
        setpoints : mapping of int to float
            Pressure line (0-based) → target pressure [Pa].
        check_line : bool, default True
            As :meth:`send_setpoint`'s.
        drain : bool, default True
            Return once the frames have left the host (:meth:`write`). A control loop does
            not wait for that at every block (on a pseudo-terminal it waits for the board
            process to read them; on a USB port for the bus); its zeros at the end do.

        Raises
        ------
        ArgumentError, DeviceError
            As :meth:`send_setpoint`.
        """
        latest = self._latest
        n_lines = (len(latest.sample.pressures_pa) or 1) if check_line and latest is not None else MAX_LINES
        for line in setpoints:
            if isinstance(line, bool) or not isinstance(line, numbers.Integral) or not 0 <= line < MAX_LINES:
                raise ArgumentError(f"line: expected a pressure line 0..{MAX_LINES - 1}, got {line!r}")
            if line >= n_lines:
                raise ArgumentError(f"line: {line} is not a pressure line of the board on {self.port} "
                                    f"(it sends {n_lines} line{'s' if n_lines > 1 else ''}, 0..{n_lines - 1})")
        if self.dialect != "binary":
            raise DeviceError(f"{self.port}: the line dialect has no set-points (SETPOINT needs the binary protocol)")
        try:
            data = b"".join(encode_setpoint(int(line), value, seq=self._next_command_seq())
                            for line, value in setpoints.items())
        except FrameError as err:
            raise ArgumentError(str(err)) from None
        if data:
            self.write(data, drain=drain)

    def send_heartbeat(self) -> None:
        """Send a HEARTBEAT: the host is alive, and feeds the board's host-silence watchdog.

        A board that was given a non-zero set-point sets every line to 0 by itself when no
        frame from the host arrives for its watchdog time (docs/formats.md, "Firmware: the
        host-silence watchdog"); a controlling host sends a heartbeat well within that time
        whether or not it has set-points to send. Thread-safe, like :meth:`send_setpoint`.
        The line dialect has no host-to-device frames (and its boards no watchdog): nothing
        is sent, as with :meth:`send`.

        Raises
        ------
        DeviceError
            The port is closed (or was never opened) or the write fails.
        """
        if self.dialect != "binary":
            return
        self.write(encode_command(FrameType.HEARTBEAT, seq=self._next_command_seq()))

    def _next_command_seq(self) -> int:
        """The next host-to-device sequence number (thread-safe: each frame gets its own)."""
        with self._write_lock:
            self._cmd_seq = (self._cmd_seq + 1) & 0xFFFF
            return self._cmd_seq

    def start(self) -> None:
        """Ask the board to stream SAMPLE frames."""
        self.send("start")
        self._streaming = True

    def stop(self) -> None:
        """Ask the board to stop streaming."""
        self._streaming = False
        self.send("stop")

    # ------------------------------------------------------------------ consumers

    @property
    def hello(self) -> Hello | None:
        """The last HELLO received."""
        return self.decoder.hello

    @property
    def n_channels(self) -> int | None:
        """Channel count from the HELLO or the line layout (None if not known yet)."""
        if self.dialect == "line":
            return self.decoder.n_channels
        return None if self.hello is None else self.hello.n_channels

    @property
    def error(self) -> str | None:
        """Why the reader stopped, if it failed."""
        return self._error

    @property
    def stats(self) -> DeviceStats:
        """Snapshot of the counters."""
        d = self.decoder
        return DeviceStats(
            frames=d.frames,
            samples=self._samples,
            crc_errors=d.crc_errors,
            malformed=d.malformed,
            lost=d.lost,
            queue_drops=self._queue_drops,
            reconnects=self._reconnects,
            overruns=d.overruns,
            bytes=d.bytes,
        )

    @property
    def queued(self) -> int:
        """Readings waiting to be taken (0 without a queue)."""
        return 0 if self._queue is None else len(self._pending) + self._queue.qsize()

    def latest(self) -> Reading | None:
        """Return the most recent reading (lossy; for live views), or None before the first."""
        return self._latest

    def add_listener(self, callback) -> None:
        """Call ``callback(event)`` for every :class:`Event` (from the reader thread).

        Parameters
        ----------
        callback : callable
            Called as ``callback(event)``.
        """
        self._listeners.append(callback)

    def _check_alive(self) -> None:
        if self._error is not None:
            raise DeviceError(self._error)
        if self._closed or self._thread is None or not self._thread.is_alive():
            raise DeviceError(f"{self.port}: device closed")

    def get(self, timeout: float | None = None) -> Reading | None:
        """Next reading from the queue, in order.

        Parameters
        ----------
        timeout : float, optional
            Longest wait [s]; None waits until a reading arrives or the device fails.

        Returns
        -------
        Reading or None
            None when ``timeout`` expired.

        Raises
        ------
        DeviceError
            Once the queue is drained, if the reader failed (disconnect without
            successful reconnect) or the driver is closed.
        """
        batch = self.get_batch(timeout=timeout, max_items=1)
        return batch[0] if batch else None

    def get_batch(self, timeout: float | None = None, max_items: int = 4096) -> list:
        """Up to ``max_items`` readings: waits up to ``timeout`` for the first, then takes what is queued.

        Parameters
        ----------
        timeout : float, optional
            Longest wait for the first reading [s]; None waits for ever.
        max_items : int, default 4096
            Most readings returned.
        """
        if self._queue is None:
            raise DeviceError(f"{self.port}: opened with queue_size=None; use latest()")
        q = self._queue
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            wait = 0.05 if deadline is None else max(0.0, min(0.05, deadline - time.monotonic()))
            if self._reading_here and not self._pending:
                self._read_here(wait)
            if self._pending:  # the caller's own reads first; the thread's queue after them
                out = self._pending[:max_items]
                del self._pending[:max_items]
                with contextlib.suppress(queue.Empty):
                    while len(out) < max_items and not self._reading_here:
                        out.append(q.get_nowait())
                return out
            if self._reading_here:  # nothing arrived within the wait
                self._check_alive()
                if deadline is not None and time.monotonic() >= deadline:
                    return []
                continue
            try:
                first = q.get(timeout=wait) if wait > 0 else q.get_nowait()
                break
            except queue.Empty:
                self._check_alive()
                if deadline is not None and time.monotonic() >= deadline:
                    return []
        out = [first]
        while len(out) < max_items:
            try:
                out.append(q.get_nowait())
            except queue.Empty:
                break
        return out

    @contextlib.contextmanager
    def reading_here(self):
        """Read the port in the calling thread while the context lasts: :meth:`get_batch` reads it.

        The reader thread pauses after the read it is in; then each :meth:`get_batch` waits
        on the port itself and decodes what arrived, so a frame reaches the caller as soon
        as its bytes do, not at the reader thread's next turn at the GIL (which a busy caller
        delays: at 2 kHz the frames then come in pairs). A caller away from :meth:`get_batch`
        longer than :attr:`here_stall_s` has the reader thread read for it meanwhile (a full
        port would lose frames), the order kept. A read error hands the port back to the
        reader thread, which reconnects as usual; the events (gaps, CRC errors) and their
        listeners are called from the caller's thread while it reads. A port without a file
        descriptor (pyserial's URLs, Windows) keeps its reader thread: the context then
        changes nothing.

        Examples
        --------
        >>> with Driver("/dev/ttyACM0") as dev, dev.reading_here():  # doctest: +SKIP
        ...     dev.start()
        ...     block = dev.get_batch(timeout=0.05)
        """
        if self._reading_here or self._thread is None or self._queue is None or _fileno(self._ser) is None:
            yield self
            return
        self._here_at = time.monotonic()
        self._reading_here = True
        try:
            yield self
        finally:
            self._reading_here = False  # the reader thread reads again; the readings not taken are served first

    def _read_here(self, wait: float) -> None:
        """Wait up to ``wait`` for the port in this thread and decode what arrived into ``_pending``.

        Once the reader thread's read in progress has ended: what the thread queued before (it
        read while this caller was away) comes first, and then it is not read here.
        """
        self._caller_in = True
        try:
            while self._thread_in:  # its read ends within read_timeout_s; it starts no other while _caller_in
                time.sleep(0.0002)
            while not self._queue.empty():  # the thread puts nothing while _caller_in: no race with get
                self._pending.append(self._queue.get_nowait())
            if not self._pending:
                self._wait_and_read(wait)
        finally:
            self._caller_in = False
            self._here_at = time.monotonic()

    def _wait_and_read(self, wait: float) -> None:
        try:
            fd = _fileno(self._ser)
            if fd is None:
                raise OSError(errno.EBADF, "the port is closed")
            ready = select.select([fd], [], [], wait)[0]
            data = os.read(fd, 65536) if ready else b""
            if ready and not data:
                raise OSError(errno.EIO, "the port reports data to read but gave none (disconnected?)")
        except (OSError, ValueError, TypeError) as err:
            log.info("%s: read in the caller's thread failed (%s); the reader thread takes the port back",
                     self.port, err)
            self._reading_here = False
            return
        if data:
            self._pending.extend(self._handle(data, time.monotonic_ns(), queued=False))

    def __iter__(self):
        """Yield readings in order until the driver is closed; raise DeviceError if the device fails."""
        while True:
            try:
                batch = self.get_batch(timeout=0.1)
            except DeviceError:
                if self._closed and self._error is None:
                    return
                raise
            yield from batch

    # ------------------------------------------------------------------ reader thread

    def _emit(self, kind: str, text: str) -> None:
        ev = Event(time.time(), kind, text)
        self.events.append(ev)
        level = logging.WARNING if kind in ("disconnect", "error", "queue_drop") else logging.INFO
        log.log(level, "%s: %s", self.port, text)
        for cb in list(self._listeners):
            try:
                cb(ev)
            except Exception:  # a listener must not kill the reader
                log.exception("event listener failed")

    def _run(self) -> None:
        while not self._closing.is_set():
            if self._reading_here and (self._caller_in or time.monotonic() - self._here_at < self.here_stall_s):
                self._closing.wait(self.read_timeout_s)  # the caller reads the port (reading_here)
                continue
            self._thread_in = True
            try:
                if self._caller_in:  # the caller came back meanwhile
                    continue
                try:
                    ser = self._ser
                    data, error = ser.read(max(1, ser.in_waiting)), None
                except Exception as err:  # noqa: BLE001 - SerialException, OSError, TypeError on a closed port
                    data, error = b"", err
                if data:
                    self._handle(data, time.monotonic_ns())
            finally:
                self._thread_in = False
            if error is not None and (self._closing.is_set() or not self._reconnect(error)):
                break  # the reconnect outside its turn (_thread_in): a caller reading here waits not for its backoff

    def _reconnect(self, err) -> bool:
        n = self.reconnect.attempts
        self._emit("disconnect", f"read failed ({_os_reason(err)}){'; reconnecting' if n else ''}")
        try:
            self._ser.close()
        except Exception:  # noqa: BLE001
            pass
        for attempt in range(1, n + 1):
            delay = min(self.reconnect.backoff_s * 2 ** (attempt - 1), 2.0)
            if self._closing.wait(delay):
                return False
            try:
                ser = self._open_serial()
            except DeviceError as exc:
                self._emit("reconnect", f"reconnect attempt {attempt}/{n} failed: {exc}")
                continue
            self._ser = ser
            self.decoder.reset()
            self._reconnects += 1
            self._emit("reconnect", f"reconnected after {attempt} attempt(s)")
            try:
                if self.handshake:
                    self.send("hello_request")
                if self._streaming:
                    self.send("start")
            except DeviceError as exc:
                self._emit("reconnect", f"could not resend commands: {exc}")
            return True
        self._error = f"{self.port}: device disconnected ({_os_reason(err)}); {n} reconnect attempt(s) failed"
        self._emit("error", self._error)
        return False

    def _unwrap(self, t_us: int | None, host_ns: int) -> int:
        if t_us is None:
            if self._first_host_ns is None:
                self._first_host_ns = host_ns
            return (host_ns - self._first_host_ns) // 1000
        last = self._last_t
        if last is None:
            self._device_us = t_us
        else:
            step = (t_us - last) & 0xFFFFFFFF
            if step >= 1 << 31:  # a jump back (device reset), not ~36 min of silence
                step -= 1 << 32
                self._emit("clock", f"device clock jumped back by {-step} us")
            self._device_us += step
        self._last_t = t_us
        return self._device_us

    def _room(self) -> bool:
        """Wait up to ``queue_block_s`` for room in the full queue; whether there is."""
        deadline = time.monotonic() + self.queue_block_s
        while self._queue.qsize() >= self._queue_size:
            if time.monotonic() >= deadline or self._closing.wait(0.001):
                return False
        return True

    def _handle(self, data: bytes, host_ns: int, *, queued: bool = True) -> list:
        """Decode ``data``; its readings go to the queue (``queued``) or are returned (``reading_here``)."""
        dec = self.decoder
        frames = dec.feed(data)
        q = self._queue if queued else None
        may_block = True
        drops = 0
        readings = []
        for f in frames:
            if type(f) is Sample:
                r = Reading(host_ns, self._unwrap(f.t_us, host_ns), f)
                self._latest = r
                self._samples += 1
                if q is None:
                    readings.append(r)
                    continue
                if q.qsize() >= self._queue_size and not (may_block and self._room()):
                    drops += 1
                    may_block = False  # block once per chunk, not once per frame
                    continue
                q.put(r)
            elif type(f) is Hello:
                self._unwrap(f.t_us, host_ns)
                self._emit(
                    "hello",
                    f"HELLO firmware={f.firmware!r} n_channels={f.n_channels} adc_bits={f.adc_bits} "
                    f"rate_hz={f.rate_hz} vref_mv={f.vref_mv}",
                )
                self._hello_event.set()
            elif type(f) is Text:
                self._unwrap(f.t_us, host_ns)
                self._emit("text", f"firmware: {f.text}")
            elif type(f) is Command or type(f) is Setpoint:
                pass  # our own commands echoed back (loop://)
        if drops:
            self._queue_drops += drops
            self._emit("queue_drop", f"recorder queue full: {drops} reading(s) dropped (total {self._queue_drops})")
        while dec.gaps:
            seq, n = dec.gaps.popleft()
            self._emit("gap", f"{n} frame(s) lost before seq {seq}")
        crc, bad, over = dec.crc_errors, dec.malformed, dec.overruns
        c0, b0, o0 = self._seen
        if crc != c0:
            self._emit("crc", f"{crc - c0} CRC error(s) (total {crc})")
        if over != o0:
            self._emit("overrun", f"{over - o0} over-long run(s) without delimiter dropped (total {over})")
        if bad - (over - o0) != b0:
            self._emit("malformed", f"{bad - b0 - (over - o0)} malformed frame(s) (total {bad})")
        self._seen = (crc, bad, over)
        return readings


def _fileno(ser) -> int | None:
    """The port's file descriptor, or None (a pyserial URL, Windows, a closed port)."""
    try:
        return ser.fileno()
    except Exception:  # noqa: BLE001 - AttributeError (no descriptor), SerialException (closed)
        return None


def _check_port_path(port: str) -> None:
    """Refuse a path that exists but is no terminal device (a directory, a regular file, a FIFO), naming what it is."""
    import stat

    if not port.strip():
        raise DeviceError("port: empty (give the board's port, e.g. /dev/ttyACM0; 'bendsense devices' lists them)")
    if "://" in port:
        return  # a pyserial URL (loop://, rfc2217://, socket://)
    try:
        mode = os.stat(port).st_mode
    except OSError:
        return  # missing or unreadable: pyserial's own message names it
    if not stat.S_ISCHR(mode):
        from bendsense._io import file_kind

        kind = file_kind(mode) or "a regular file"
        raise DeviceError(f"{port}: {kind}, not a serial port (give the board's port, e.g. /dev/ttyACM0; "
                          "'bendsense devices' lists them)")


def _os_reason(err: Exception) -> str:
    """Why a port operation failed, for a person: ``Input/output error``, not ``write failed: [Errno 5] ...``."""
    if isinstance(err, OSError) and err.strerror:
        return err.strerror
    return re.sub(r"^(?:write|read) failed: |\[Errno \d+\] ", "", str(err)) or type(err).__name__
