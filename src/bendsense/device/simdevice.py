"""A simulated sensor board on a pseudo-terminal, speaking the binary wire protocol.

:class:`SimulatedDevice` opens a pseudo-terminal pair and plays the firmware on the
master side: it answers HELLO_REQUEST with HELLO, streams SAMPLE frames at ``rate_hz``
after START (or at once with ``autostart=True``), stops on STOP, passes SETPOINT frames to
its source (a simulated gripper's pressure regulators), keeps a host-silence watchdog
over them (a host that drove a line and then sends nothing for ``watchdog_ms``: set-point
0 on every line, said in a TEXT frame), and can misbehave on
purpose: drop a frame (its ``seq`` is skipped), corrupt one (one bit flipped), truncate
one (cut short, no trailing delimiter), or disconnect (close the master) after a given
number of frames. Every injection is counted exactly in :attr:`SimulatedDevice.stats`,
so tests can check a receiver's counters against it. Any program opens ``.port``
(e.g. ``/dev/pts/7``) as if it were the real board.
"""

from __future__ import annotations

import errno
import fcntl
import itertools
import logging
import math
import os
import random
import select
import struct
import termios
import threading
import time
import tty
from dataclasses import dataclass

import numpy as np

from bendsense.errors import DeviceError
from bendsense.wire.frames import Command, Decoder, FrameType, Setpoint, encode_hello, encode_sample, encode_text

__all__ = [
    "SimulatedDevice",
    "SimStats",
    "Faults",
    "Firmware",
    "default_source",
    "scripted_board",
    "ramp_source",
    "DEFAULT_WATCHDOG_MS",
]

log = logging.getLogger("bendsense.device.sim")

USB_FULL_SPEED_BYTES_PER_S = 1_216_000
"""Most a USB full-speed CDC link carries: 19 bulk packets of 64 bytes per 1 ms USB frame [bytes/s]."""


def max_rate_hz(n_channels: int = 16, n_lines: int = 0) -> int:
    """Highest frame rate a board of ``n_channels`` can send over a USB full-speed link [Hz].

    A SAMPLE frame on the wire is its payload (16 + 2 N bytes; a version-2 SAMPLE 1 + 4
    n_lines more), the CRC (2), COBS's overhead (1 byte per 254) and two delimiters: 53
    bytes for 16 channels, so at most ~22,900 frames/s; and the HELLO's ``rate_hz``
    field is a u16 (65535).

    Parameters
    ----------
    n_channels : int, default 16
        Channels per SAMPLE.
    n_lines : int, default 0
        Pressure lines of a version-2 SAMPLE (0: version 1).
    """
    body = 16 + 2 * int(n_channels) + 2 + (1 + 4 * int(n_lines) if n_lines else 0)
    wire = body + 1 + body // 254 + 2
    return int(min(USB_FULL_SPEED_BYTES_PER_S // wire, 0xFFFF))


DEFAULT_WATCHDOG_MS = 1000.0
"""The board's host-silence watchdog [ms]: twenty heartbeat periods of ``bendsense control``
(:data:`bendsense.control.loop.HEARTBEAT_S`). It is the backstop for a host that is gone,
not a deadline for one that is slow: a Python loop on a shared machine stalls for hundreds
of milliseconds (a 3-finger loop at 1 kHz took 0.83 s for one block on a 2-core machine at
load 7), and the loop's own stops watch its timing. With the regulators' 25 ms lag a line
is empty (below 1 %) about 1.1 s after the host's last frame."""

_MAX_PENDING = 64 * 1024  # bytes queued for the pseudo-terminal before frames count as TX overflow


def default_source(
    n_channels: int = 16, adc_bits: int = 12, rate_hz: float = 500.0, seed=None, *, config=None, **options
):
    """Return the default frame source: the virtual sensor of :mod:`bendsense.sim`.

    The frames of the ``time-varying`` scenario
    (:func:`bendsense.sim.scenarios.time_varying_frames`): the pressure ramps between 0
    and 100 kPa and back every 5 s while a contact force normal to the tip switches on
    and off. Frame ``k`` is the scenario at ``t = k / rate_hz``, so the same seed and
    rate give the same frames, and a receiver can recompute the ground truth of frame
    ``k`` with ``time_varying_frames(config, rate_hz, seed, truth=True)``.

    Parameters
    ----------
    n_channels : int
        Channels N. The config's sensor when it has N segments (the paper's has 16);
        otherwise N equal segments over the same sensor length.
    adc_bits : int
        ADC resolution [bit].
    rate_hz : float
        Frame rate [Hz] (the time step of the scenario).
    seed : int, optional
        Seed of the sensor hardware (offsets, gains) and of the noise; None: 0, the
        default of ``bendsense simulate``, so that ``bendsense simulate calibration``
        calibrates this sensor.
    config : Config, optional
        The true actuator and sensor; default the paper's prototype.
    **options
        Passed to :func:`~bendsense.sim.scenarios.time_varying_frames` (``contact_n``,
        ``noise_counts``, ``duration_s``, model mismatch, ...).

    Returns
    -------
    iterator
        Of ``(pressure_pa, adc_counts)``; endless unless ``duration_s`` is given. Its first
        frame is already computed (the slow first run after an install happens here).
    """
    from bendsense.sim.scenarios import time_varying_frames
    from bendsense.sim.sensor import VirtualSensor

    config = _board_config(config, n_channels)
    seed = 0 if seed is None else seed
    if adc_bits != 12 and "sensor" not in options:
        options["sensor"] = VirtualSensor.from_config(
            config.sensor, noise_counts=options.pop("noise_counts", 1.5), adc_bits=adc_bits, seed=seed
        )
    frames = time_varying_frames(config, rate_hz, seed, **options)
    # the first block is simulated here, before the board exists: on the first run after an
    # install it compiles the beam kernels (seconds), which must not happen while a
    # receiver that opened the printed port waits for frames
    first = next(frames, None)
    return frames if first is None else itertools.chain([first], frames)


def _board_config(config, n_channels: int):
    """The config (default the paper's) with an N-channel sensor: N equal segments over the same length if N differs."""
    import dataclasses

    from bendsense.config import load_config

    config = load_config() if config is None else config
    sensor = config.sensor
    if n_channels != sensor.n_segments:
        lengths = (sensor.length_m / n_channels,) * n_channels
        config = dataclasses.replace(config, sensor=dataclasses.replace(sensor, n_segments=n_channels,
                                                                        segment_lengths_m=lengths))
    return config


def scripted_board(n_channels: int = 16, adc_bits: int = 12, rate_hz: float = 500.0, seed=None, *, config=None,
                   truth: bool = False, **options):
    """The single actuator's board of ``sim-device``: :func:`default_source` until the host drives line 0.

    A :class:`~bendsense.sim.gripper.ScriptedBoard`: the time-varying scenario frame for
    frame while the host sends no SETPOINT; from the first SETPOINT on line 0, the free
    actuator (no object) on the same sensor hardware, its pressure regulator following the
    host (and the watchdog). Model errors act on both.

    Parameters
    ----------
    n_channels, adc_bits, rate_hz, seed, config
        As :func:`default_source`.
    truth : bool
        Every frame carries its truth as the truth file's columns
        (:func:`bendsense.sim.truth.truth_columns`).
    **options
        Passed to :func:`default_source` (``contact_s_m``, ``noise_counts``, the model errors
        ``ei_error``, ``k0_error``, ``base_rotation_rad_per_rad``, ``hysteresis_pa``, ...);
        the model errors and ``noise_counts`` also to the free actuator's
        :class:`~bendsense.sim.gripper.GraspBoard`.

    Returns
    -------
    ScriptedBoard
    """
    from bendsense.sim.actuator import MODEL_ERRORS
    from bendsense.sim.gripper import GraspBoard, ScriptedBoard
    from bendsense.sim.truth import scenario_truth

    shared = {k: v for k, v in options.items() if k in (*MODEL_ERRORS, "noise_counts")}
    # the free actuator's tables first: a bad model error fails here, before the scenario's first block
    board = GraspBoard(_board_config(config, n_channels), [None], rate_hz=rate_hz, seed=seed, adc_bits=adc_bits,
                       **shared)
    script = default_source(n_channels, adc_bits, rate_hz, seed, config=config, truth=truth, **options)
    return ScriptedBoard(scenario_truth(script) if truth else script, board)


def ramp_source(n_channels: int = 16, adc_bits: int = 12, pressure_pa: float | None = 20_000.0):
    """Return a synthetic source whose counts encode the frame index.

    Channel ``c`` of frame ``k`` is ``(k + 100 c) mod 2**adc_bits``, so a receiver can
    check exactly which frames arrived.

    Parameters
    ----------
    n_channels : int, default 16
        Number of channels.
    adc_bits : int, default 12
        ADC resolution [bits].
    pressure_pa : float or None, default 20000.0
        Pressure of every frame [Pa]; None for "no reading".

    Returns
    -------
    callable
        ``source(k) -> (pressure_pa, adc_counts)``.
    """
    offsets = np.arange(n_channels, dtype=np.int64) * 100
    mask = (1 << adc_bits) - 1

    def source(k: int):
        return pressure_pa, (k + offsets) & mask

    return source


@dataclass(frozen=True, kw_only=True)
class Faults:
    """How a :class:`SimulatedDevice` misbehaves on purpose (every injection is counted in its stats).

    Attributes
    ----------
    drop, corrupt, truncate : float
        Probability per SAMPLE frame of each fault (at most one per frame): skipped (its
        ``seq`` consumed, nothing sent), one bit flipped (always a CRC error at the
        receiver), cut short (no trailing delimiter). Together at most 1.
    disconnect_after : int, optional
        Close the master after this many SAMPLE frames were generated (once the
        receiver has read them, waiting at most 0.5 s), as if the cable were pulled.
    seed : int, optional
        Seed of the fault draws.

    Raises
    ------
    DeviceError
        For a probability outside [0, 1] or a sum above 1.
    """

    drop: float = 0.0
    corrupt: float = 0.0
    truncate: float = 0.0
    disconnect_after: int | None = None
    seed: int | None = None

    def __post_init__(self):
        for name in ("drop", "corrupt", "truncate"):
            p = getattr(self, name)
            if not 0.0 <= p <= 1.0:
                raise DeviceError(f"{name}: expected a probability in [0, 1], got {p!r}")
            object.__setattr__(self, name, float(p))
        if self.drop + self.corrupt + self.truncate > 1.0:
            raise DeviceError(f"drop + corrupt + truncate: expected <= 1, got "
                              f"{self.drop + self.corrupt + self.truncate:g}")


@dataclass(frozen=True, kw_only=True)
class Firmware:
    """What a :class:`SimulatedDevice`'s firmware says of itself in HELLO, and where its counters start.

    Attributes
    ----------
    name : str
        The firmware string of HELLO.
    vref_mv : int
        The ADC reference voltage of HELLO [mV].
    start_seq, start_t_us : int
        First sequence number and device clock [us]: a board that has been running a
        while (to exercise the receiver's unwrapping of both).
    """

    name: str = "bendsense-sim 1"
    vref_mv: int = 3300
    start_seq: int = 0
    start_t_us: int = 0


@dataclass(frozen=True)
class SimStats:
    """Exact counts of what a :class:`SimulatedDevice` did.

    Attributes
    ----------
    generated : int
        SAMPLE frames produced (each consumed one ``seq``).
    sent : int
        SAMPLE frames written intact.
    dropped : int
        Frames skipped on purpose (``seq`` consumed, nothing sent).
    corrupted : int
        Frames sent with one bit flipped (always a CRC error at the receiver).
    truncated : int
        Frames cut short (no trailing delimiter).
    tx_overflow : int
        Frames not sent because nobody read the pseudo-terminal (backpressure).
    hellos, texts : int
        HELLO and TEXT frames sent (they consume ``seq`` too).
    commands : int
        Commands received (SETPOINTs included).
    disconnected : bool
        The master was closed on purpose.
    setpoints : int
        SETPOINT frames the source took (a line it has, a finite value).
    watchdog_trips : int
        Times the host-silence watchdog set every line to 0.
    """

    generated: int
    sent: int
    dropped: int
    corrupted: int
    truncated: int
    tx_overflow: int
    hellos: int
    texts: int
    commands: int
    disconnected: bool
    setpoints: int = 0
    watchdog_trips: int = 0


class SimulatedDevice:
    """The sensor board, simulated on a pseudo-terminal.

    Parameters
    ----------
    source : iterable, callable or None
        Per frame ``(pressure_pa or None, adc_counts)``, or ``(pressures, adc_counts,
        truth)``: an iterable (streaming ends when it is exhausted) or a callable
        ``source(k)`` of the frame index ``k``. A tuple of pressures (one per line) is
        sent as a version-2 SAMPLE; ``truth`` (a dict) goes to ``truth``. A source with
        a method ``setpoint(line, pressure_pa) -> bool`` takes the SETPOINT frames (a
        :class:`~bendsense.sim.gripper.GraspBoard`); other sources answer them with a
        TEXT line. A source with a method ``release()`` (set-point 0 on every line) gets
        the watchdog. None: :func:`default_source`, the virtual sensor (seed 0).
    rate_hz : float
        Frame rate [Hz].
    n_channels, adc_bits : int
        Reported in HELLO; counts are masked to ``adc_bits``.
    faults : Faults, optional
        Dropped, corrupted and truncated frames, a disconnect, and their seed; default
        ``Faults()``: none.
    autostart : bool
        Stream from the start without waiting for START (a free-running board).
    max_frames : int, optional
        Stop streaming after this many generated frames.
    firmware : Firmware, optional
        Its name and reference voltage in HELLO, and its first sequence number and
        device clock; default ``Firmware()``.
    truth : TruthWriter, optional
        Gets ``write(seq, t_us, truth)`` for every SAMPLE frame generated (dropped ones
        too: match rows by ``seq``) and ``flush()`` after every burst
        (:class:`bendsense.sim.truth.TruthWriter`).
    watchdog_ms : float, default :data:`DEFAULT_WATCHDOG_MS`
        The host-silence watchdog [ms] (0: none). While the host holds a line at a
        non-zero set-point, every frame it sends (any type) restarts the timer; when
        none arrives for ``watchdog_ms`` the board calls the source's ``release()``,
        sends a TEXT frame saying so and logs a warning. The next non-zero SETPOINT
        arms it again. Only a source with ``release()`` has it.

    Attributes
    ----------
    burst : int
        Most frames written in one go when the sender is behind (64).

    Notes
    -----
    The device clock of frame ``k`` is exactly ``firmware.start_t_us + round(k * 1e6 /
    rate_hz)`` (mod 2**32), whatever the host's timing jitter; frames are paced against
    the host clock and sent in bursts when the thread wakes up late.
    """

    burst = 64

    def __init__(
        self,
        source=None,
        *,
        rate_hz: float = 500.0,
        n_channels: int = 16,
        adc_bits: int = 12,
        faults: Faults | None = None,
        autostart: bool = False,
        max_frames: int | None = None,
        firmware: Firmware | None = None,
        truth=None,
        watchdog_ms: float = DEFAULT_WATCHDOG_MS,
    ):
        if not rate_hz > 0:
            raise DeviceError(f"rate_hz: expected > 0, got {rate_hz!r}")
        if rate_hz > max_rate_hz(n_channels):
            # the board would simulate rate_hz x 0.1 s of frames per block and queue what the link cannot carry
            raise DeviceError(f"rate_hz: expected at most {max_rate_hz(n_channels):,} Hz (what a USB full-speed "
                              f"link carries for {n_channels} channels), got {rate_hz:g}")
        faults = Faults() if faults is None else faults
        firmware = Firmware() if firmware is None else firmware
        for name, value, kind in (("faults", faults, Faults), ("firmware", firmware, Firmware)):
            if not isinstance(value, kind):
                raise DeviceError(f"{name}: expected a {kind.__name__}, got {type(value).__name__}")
        if isinstance(watchdog_ms, bool) or not isinstance(watchdog_ms, (int, float)) \
                or not 0 <= watchdog_ms < float("inf"):
            raise DeviceError(f"watchdog_ms: expected a time >= 0 [ms] (0: no watchdog), got {watchdog_ms!r}")
        if source is None:
            source = default_source(n_channels=n_channels, adc_bits=adc_bits, rate_hz=rate_hz)
        self._source_fn = source if callable(source) and not hasattr(source, "__next__") else None
        self._source_it = None if self._source_fn is not None else iter(source)
        self._on_setpoint = getattr(source, "setpoint", None)
        self._release = getattr(source, "release", None)
        self.watchdog_ms = float(watchdog_ms) if self._release is not None else 0.0
        self._driven = set()  # lines the host holds at a non-zero set-point: what the watchdog guards
        self._heard = 0.0  # when the last frame from the host was read (time.monotonic)
        self._truth = truth
        self.rate_hz = float(rate_hz)
        self.n_channels = int(n_channels)
        self.adc_bits = int(adc_bits)
        self.faults = faults
        self.autostart = bool(autostart)
        self.max_frames = max_frames
        self.firmware = firmware
        self._rng = random.Random(faults.seed)
        self._seq = int(firmware.start_seq) & 0xFFFF
        self._t0_us = int(firmware.start_t_us)
        self._mask = (1 << self.adc_bits) - 1
        self._lock = threading.Lock()
        self._counts = dict.fromkeys(
            ("generated", "sent", "dropped", "corrupted", "truncated", "tx_overflow", "hellos", "texts", "commands",
             "setpoints", "watchdog_trips"), 0
        )
        self._disconnected = False
        self._stop = threading.Event()
        self.finished = threading.Event()
        """Set when the source is exhausted or ``max_frames`` reached (and the receiver has read
        the last frame, waiting at most 1 s), or the device disconnected."""
        self._exhausted = False
        self._streaming = self.autostart
        self._pending = bytearray()
        self._texts = []
        self._decoder = Decoder()
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.port = os.ttyname(self._slave)
        self._thread = None

    # ------------------------------------------------------------------ public

    @property
    def stats(self) -> SimStats:
        """Exact counts so far."""
        with self._lock:
            return SimStats(**self._counts, disconnected=self._disconnected)

    @property
    def streaming(self) -> bool:
        """True while SAMPLE frames are being sent."""
        return self._streaming

    def start(self) -> SimulatedDevice:
        """Start the device thread (done by ``with``)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"bendsense-sim {self.port}", daemon=True)
            self._thread.start()
        return self

    def send_text(self, text: str) -> None:
        """Have the firmware send a TEXT log line.

        Parameters
        ----------
        text : str
            The log line.
        """
        with self._lock:
            self._texts.append(str(text))

    def disconnect(self) -> None:
        """Close the master now, as if the USB cable were pulled."""
        self._stop_thread()
        self._close_fds(disconnected=True)

    def close(self) -> None:
        """Stop the thread and close the pseudo-terminal."""
        self._stop_thread()
        self._close_fds(disconnected=False)

    def __enter__(self) -> SimulatedDevice:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ internals

    def _stop_thread(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)

    def _close_fds(self, disconnected: bool) -> None:
        with self._lock:
            if self._master is None:
                return
            for fd in (self._master, self._slave):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self._master = self._slave = None
            if disconnected:
                self._disconnected = True
        self.finished.set()

    def _t_us(self, k: int) -> int:
        return self._t0_us + round(k * 1e6 / self.rate_hz)

    def _offset_s(self, k: int) -> float:
        """When frame ``k`` is due, after the first one [s] (host time)."""
        return k / self.rate_hz

    def _sample_header(self, k: int) -> tuple:
        """``(seq, t_us, status, drops)`` of SAMPLE ``k`` (consumes its sequence number).

        ``drops``: frames lost before this board's own (its ``tx_drops`` adds them; a replay's recorded ones).
        """
        return self._next_seq(), self._t_us(k), 0, 0

    def _next_seq(self) -> int:
        s = self._seq
        self._seq = (s + 1) & 0xFFFF
        return s

    def _frame_values(self, k: int):
        if self._source_fn is not None:
            return self._source_fn(k)
        return next(self._source_it)

    def _run(self) -> None:
        try:
            self._loop()
        except Exception:  # the device must not die silently
            log.exception("simulated device failed")
            self._close_fds(disconnected=True)
        finally:
            self.finished.set()

    def _loop(self) -> None:
        k = 0  # next frame index
        t_start = None
        while not self._stop.is_set():
            # read commands
            try:
                data = os.read(self._master, 4096)
            except BlockingIOError:
                data = b""
            except OSError as err:
                if err.errno == errno.EIO:  # no slave open at the moment: not an error for a board
                    data = b""
                else:
                    raise
            frames = self._decoder.feed(data)
            if frames:
                self._heard = time.monotonic()
            for f in frames:
                if type(f) is Command:
                    self._on_command(f.kind, k)
                elif type(f) is Setpoint:
                    self._setpoint(f)
            self._watch()
            with self._lock:
                texts, self._texts = self._texts, []
            for text in texts:
                self._queue_bytes(encode_text(self._next_seq(), self._t_us(k), text))
                self._counts["texts"] += 1
            # produce the frames that are due
            now = time.monotonic()
            if not self._streaming:
                t_start = None
            elif t_start is None:
                t_start = now - self._offset_s(k)  # (re)start without a burst of stale frames
            if self._streaming and not self._exhausted:
                for _ in range(self.burst):
                    if self._offset_s(k) > now - t_start:
                        break
                    if self.max_frames is not None and k >= self.max_frames:
                        self._exhausted = True
                        break
                    if self.faults.disconnect_after is not None and k >= self.faults.disconnect_after:
                        self._flush(wait_s=0.5)
                        self._wait_read(0.5)
                        self._close_fds(disconnected=True)
                        return
                    try:
                        values = self._frame_values(k)
                    except StopIteration:
                        self._exhausted = True
                        break
                    self._produce(k, *values)
                    k += 1
            if self._truth is not None:  # the rows of a burst reach the file before its frames the port
                self._truth.flush()
            self._flush()
            if self._exhausted and not self.finished.is_set():
                self._flush(wait_s=1.0)
                self._wait_read(1.0)
                self.finished.set()
            # sleep until the next frame is due or a command arrives
            if self._master is None:
                return
            wait = 0.02
            if self._streaming and t_start is not None and not self._exhausted:
                wait = max(0.0, min(wait, t_start + self._offset_s(k) - time.monotonic()))
            w = [self._master] if self._pending else []
            try:
                select.select([self._master], w, [], wait)
            except (OSError, ValueError):
                return

    def _on_command(self, kind, k: int) -> None:
        with self._lock:
            self._counts["commands"] += 1
        if kind == FrameType.HELLO_REQUEST:
            frame = encode_hello(
                self._next_seq(),
                self._t_us(k),
                self.n_channels,
                self.adc_bits,
                round(self.rate_hz) & 0xFFFF,
                int(self.firmware.vref_mv),
                self.firmware.name,
            )
            with self._lock:
                self._counts["hellos"] += 1
            self._queue_bytes(frame, force=True)
        elif kind == FrameType.START:
            self._streaming = True
        elif kind == FrameType.STOP:
            self._streaming = False

    def _setpoint(self, frame) -> None:
        """A SETPOINT: to the source's regulators, or a TEXT line saying why not."""
        with self._lock:
            self._counts["commands"] += 1
        if self._on_setpoint is None:
            why = "this board's pressure follows its scenario (sim-device --source sensor simulates a regulator)"
        elif self._on_setpoint(frame.line, frame.pressure_pa):
            with self._lock:
                self._counts["setpoints"] += 1
            if frame.pressure_pa > 0:
                self._driven.add(frame.line)
            else:
                self._driven.discard(frame.line)
            return
        else:
            why = "no such pressure line"
        with self._lock:
            self._texts.append(f"SETPOINT line {frame.line} {frame.pressure_pa} Pa ignored: {why}")

    def _watch(self) -> None:
        """The host-silence watchdog: a host that holds a line up and falls silent gets every line set to 0."""
        if not self._driven or not self.watchdog_ms:
            return
        silent_ms = (time.monotonic() - self._heard) * 1e3
        if silent_ms <= self.watchdog_ms:
            return
        self._release()
        text = (f"watchdog: no frame from the host for {math.ceil(silent_ms)} ms (limit {self.watchdog_ms:g} ms) "
                f"while it held line{'s' if len(self._driven) > 1 else ''} "
                f"{', '.join(map(str, sorted(self._driven)))} up: "
                "set-point 0 on every pressure line")
        self._driven.clear()
        log.warning("%s: %s", self.port, text)
        with self._lock:
            self._counts["watchdog_trips"] += 1
            self._texts.append(text)

    def _produce(self, k: int, pressure, adc, truth=None) -> None:
        seq, t_us, status, drops = self._sample_header(k)
        counts = np.asarray(adc, dtype=np.int64) & self._mask
        if self._truth is not None:
            self._truth.write(seq, t_us & 0xFFFFFFFF, {} if truth is None else truth)
        r = self._rng.random()
        drop, corrupt, truncate = self.faults.drop, self.faults.corrupt, self.faults.truncate
        with self._lock:
            self._counts["generated"] += 1
        if r < drop:
            with self._lock:
                self._counts["dropped"] += 1
            return
        # a dropped frame is one the firmware could not send: it counts it in tx_drops
        tx_drops = (drops + self._counts["dropped"] + self._counts["tx_overflow"]) & 0xFFFF
        if isinstance(pressure, tuple):  # one per line: a version-2 SAMPLE
            frame = encode_sample(seq, t_us, counts.tolist(), status=status, tx_drops=tx_drops, pressures_pa=pressure)
        else:
            frame = encode_sample(seq, t_us, counts.tolist(), pressure_pa=pressure, status=status, tx_drops=tx_drops)
        kind = "sent"
        if r < drop + corrupt:
            frame = self._flip_one_bit(frame)
            kind = "corrupted"
        elif r < drop + corrupt + truncate:
            frame = frame[: self._rng.randrange(2, len(frame) - 1)]
            kind = "truncated"
        if self._queue_bytes(frame):
            with self._lock:
                self._counts[kind] += 1

    def _flip_one_bit(self, frame: bytes) -> bytes:
        """Flip one bit of a stuffed data byte, never making a 0x00.

        That is one bit error in the body, which CRC-16 always detects, and no new
        delimiter, so the receiver sees exactly one bad frame.
        """
        enc = bytearray(frame)
        code_positions = set()
        i = 1
        while i < len(enc) - 1:  # walk the COBS code bytes
            code_positions.add(i)
            i += enc[i]
        candidates = [j for j in range(1, len(enc) - 1) if j not in code_positions]
        while True:
            j = self._rng.choice(candidates)
            bit = 1 << self._rng.randrange(8)
            if enc[j] ^ bit:
                enc[j] ^= bit
                return bytes(enc)

    def _wait_read(self, timeout_s: float) -> None:
        """Wait until the receiver has read what was sent.

        A disconnect after N frames then loses none of them (a cable pulled between frames).
        """
        end = time.monotonic() + timeout_s
        empty_since = None
        while time.monotonic() < end:
            try:
                waiting = struct.unpack("i", fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0"))[0]
            except OSError:
                return
            now = time.monotonic()
            if waiting:
                empty_since = None
            elif empty_since is None:
                empty_since = now
            elif now - empty_since > 0.05:  # bytes may still sit in the pty's flip buffer briefly
                return
            time.sleep(0.005)

    def _queue_bytes(self, frame: bytes, force: bool = False) -> bool:
        if not force and len(self._pending) > _MAX_PENDING:
            with self._lock:
                self._counts["tx_overflow"] += 1
            return False
        self._pending += frame
        return True

    def _flush(self, wait_s: float = 0.0) -> None:
        deadline = time.monotonic() + wait_s
        while self._pending and self._master is not None:
            try:
                n = os.write(self._master, self._pending)
                del self._pending[:n]
            except BlockingIOError:
                pass
            except OSError as err:
                if err.errno == errno.EIO:
                    return
                raise
            if not self._pending or time.monotonic() >= deadline:
                return
            select.select([], [self._master], [], max(0.0, deadline - time.monotonic()))
