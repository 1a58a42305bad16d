"""The control loop: per block of frames, process, control, clip, send; and let go whatever happens.

:func:`run` drains the driver's queue (every frame, in order, as a block of what has
arrived since the previous one: one frame per block while the loop keeps up with the
board, more when it falls behind), processes the block (a
:class:`~bendsense.pipeline.LiveProcessor`, or a gripper's processor: tracking in filter
mode), checks it (:class:`~bendsense.control.safety.Guard`), calls the controller, clips
its set-points to ``[0, max_pressure_pa]`` and sends them
(:meth:`~bendsense.device.driver.Driver.send_setpoint`), then records the block if asked.
Lines the controller does not drive get set-point 0 with the first block and are held
there. Whatever ends the loop — its time, a stop event, Ctrl-C, SIGTERM, SIGHUP (the
terminal closed), SIGQUIT, a safety stop,
an error in the controller or the processor, a failing device — set-point 0 goes first,
before anything else is closed, to every line the config has, the loop drove or the board
ever reported; each line's zero is recorded (:class:`LineZero`: sent, or why not) and the
time from the stop to the last zero written is measured
(:attr:`ControlResult.zero_latency_s`); more stop signals while it zeros are held off
until every line has its zero and its record (:func:`bendsense.stop_signals.deferred`).
Then it watches the board's pressures fall for up to ``Safety.confirm_s`` and records,
line by line, whether each did. While it runs it sends a HEARTBEAT at least every
:data:`HEARTBEAT_S`, set-points or not, so that a board's host-silence watchdog lets go of
every line by itself only when the loop is gone (killed, hung, the cable pulled). The
safety model in full is :mod:`bendsense.control.safety`'s.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import signal
import sys
import time
from dataclasses import dataclass

import numpy as np

from bendsense.control.safety import ControlStop, Guard, Safety
from bendsense.errors import ArgumentError, DeviceError
from bendsense.pipeline.readings import sample_lines
from bendsense.stop_signals import STOP_SIGNALS, deferred, handled

__all__ = ["run", "ControlResult", "LineZero", "zero_report", "DEFAULT_MAX_PRESSURE_PA", "HEARTBEAT_S"]

log = logging.getLogger("bendsense.control")


@dataclass(frozen=True)
class LineZero:
    """What became of one line's set-point 0 at the end of a control session.

    Attributes
    ----------
    line : int
        The pressure line (0-based).
    sent : bool
        The SETPOINT 0 was written to the port.
    error : str or None
        Why it could not be sent (None when sent).
    reported : bool
        The board's latest frame reports this line's pressure, so a reader of the board
        can confirm that it falls; False: the board does not report it (it stopped, or
        never did) and nothing on the host can confirm it.
    fell : bool or None
        The reported pressure fell to ``Safety.pressure_tolerance_pa`` or below within
        ``Safety.confirm_s`` of the last zero; None: not watched (not sent, not reported,
        or ``confirm_s`` 0), or no frame reported the line during the watch.
    pressure_pa : float
        The line's last reported pressure when the watch ended [Pa] (NaN: not watched).
    after_s : float
        How long the watch lasted after the last zero [s] (NaN: not watched).
    """

    line: int
    sent: bool
    error: str | None
    reported: bool
    fell: bool | None = None
    pressure_pa: float = math.nan
    after_s: float = math.nan


@dataclass(frozen=True)
class ControlResult:
    """What a control session did.

    Attributes
    ----------
    frames : int
        Frames processed.
    blocks : int
        Blocks (controller calls).
    outcome : str
        How it ended: ``duration reached``, ``stopped``, ``interrupted``, or the reason
        of a safety stop or an error.
    lines : tuple of int
        The pressure lines set-point 0 went to at the end (every line of the config, every
        line the loop drove, every line the board reported).
    max_setpoint_pa : float
        The highest set-point sent [Pa].
    clipped : int
        Set-points the controller asked beyond ``[0, max_pressure_pa]`` (sent clipped).
    zero_latency_s : float
        From the stop (noticed by the loop) to the last zero set-point written [s]; NaN
        when the zeros could not be sent.
    stopped_at_s : float
        When the loop noticed the stop (``time.perf_counter()``) [s].
    loop_s : ndarray, shape (blocks,)
        Wall time of each block: process, check, control, send [s] (recording excluded).
    process_s : ndarray, shape (blocks,)
        Of that, the processor's (``process_readings``) [s]: the rest is the loop's own.
    block_frames : ndarray of int, shape (blocks,)
        Frames of each block.
    block_reads : ndarray of int, shape (blocks,)
        Reads of the port each block's frames came in (their distinct arrival times). The
        loop reads the port itself (:meth:`~bendsense.device.driver.Driver.reading_here`): one
        read a block, whose frames arrived while the loop was busy with the block before (or
        were sent together); more than one only in the first block (what the reader thread
        had queued) or with a driver that reads on its own thread (then ``block_reads`` > 1:
        the loop was behind).
    zeros : tuple of LineZero
        Each line's set-point 0 at the end, by line: sent, or why not; whether its pressure fell.
    held : tuple of int
        Lines the controller never drove, held at set-point 0 from the first block.
    """

    frames: int
    blocks: int
    outcome: str
    lines: tuple
    max_setpoint_pa: float
    clipped: int
    zero_latency_s: float
    stopped_at_s: float
    loop_s: np.ndarray
    process_s: np.ndarray
    block_frames: np.ndarray
    block_reads: np.ndarray
    zeros: tuple = ()
    held: tuple = ()

    @property
    def per_frame_s(self) -> float:
        """Mean loop time per frame [s]."""
        return float(np.sum(self.loop_s) / max(self.frames, 1))

    @property
    def unsent(self) -> tuple:
        """The lines whose set-point 0 could not be sent."""
        return tuple(z.line for z in self.zeros if not z.sent)

    @property
    def high(self) -> tuple:
        """The lines whose reported pressure did not fall after their set-point 0."""
        return tuple(z.line for z in self.zeros if z.fell is False)


def _names(lines) -> str:
    return f"line{'s' if len(lines) > 1 else ''} {', '.join(str(k) for k in lines)}"


def zero_report(result: ControlResult) -> str:
    """What became of every line's set-point 0, in one clause for a message.

    ``set-point 0 sent on every pressure line (0, 1, 2)`` when every write succeeded;
    otherwise the lines sent and, apart, those whose zero could not be sent, with why;
    lines whose pressure the board does not report are named as not confirmed, and those
    whose reported pressure did not fall after the zero (``line 2 did not fall: 46 kPa after
    0.5 s``).

    Parameters
    ----------
    result : ControlResult
        A finished session's result.
    """
    sent = [z.line for z in result.zeros if z.sent]
    failed = [z for z in result.zeros if not z.sent]
    if not failed:
        text = f"set-point 0 sent on every pressure line ({', '.join(str(k) for k in sent)})"
    else:
        why = "; ".join(sorted({z.error for z in failed}))
        text = (f"set-point 0 sent on {_names(sent)}; " if sent else "") + \
            f"set-point 0 could NOT be sent on {_names([z.line for z in failed])} ({why}): it may still be pressurised"
    unconfirmed = [z.line for z in result.zeros if z.sent and not z.reported]
    if unconfirmed:
        whose = "their" if len(unconfirmed) > 1 else "its"
        text += f"; {_names(unconfirmed)} not confirmed (the board does not report {whose} pressure)"
    silent = [z.line for z in result.zeros if z.fell is None and math.isfinite(z.after_s)]
    if silent:
        text += f"; {_names(silent)} not confirmed (no frame from the board after the zero)"
    for z in result.zeros:
        if z.fell is False:
            text += f"; line {z.line} did not fall: {z.pressure_pa / 1e3:.3g} kPa after {z.after_s:.2g} s"
    return text


#: the interpreter's thread switch interval while the loop runs [s] (Python's default is 5 ms): a stop
#: noticed while the board's reader thread holds the GIL must not wait that long for it
SWITCH_INTERVAL_S = 2e-4
#: the longest the loop waits without a HEARTBEAT to the board [s]: a twentieth of the simulated board's watchdog
#: (:data:`bendsense.device.simdevice.DEFAULT_WATCHDOG_MS`); a block that takes longer delays the next one
HEARTBEAT_S = 0.05


@contextlib.contextmanager
def _prompt_threads():
    """Switch threads every :data:`SWITCH_INTERVAL_S` while the loop runs (the previous interval after)."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(min(previous, SWITCH_INTERVAL_S))
    try:
        yield
    finally:
        sys.setswitchinterval(previous)


@contextlib.contextmanager
def _signals_stop(noted: list):
    """Every stop signal raises KeyboardInterrupt in the loop, and is noted in ``noted`` for the loop to check.

    In the main thread, for each stop signal not ignored: the signal is noted, then the
    handler there before acts (the command line's notes it for the exit status and raises
    the first; Python's SIGINT handler raises); a signal whose default would kill the
    process without the zeros (SIGTERM, SIGHUP, SIGQUIT outside the command line), or
    whose handler did not raise (a later one), raises KeyboardInterrupt here. The loop
    checks ``noted`` at every turn (:func:`_loop`): a KeyboardInterrupt that something
    under it swallowed (seen under load: the first Ctrl-C lost, the loop holding the force
    on, the later signals only noted) still stops it. The previous handlers come back after.
    """
    previous = {signum: signal.getsignal(signum) for signum in STOP_SIGNALS}

    def interrupt(signum, frame):
        noted.append(signum)
        before = previous.get(signum)
        if callable(before):
            before(signum, frame)
        raise KeyboardInterrupt

    with handled(interrupt):
        yield


def _lines(processor, n_lines) -> tuple:
    if n_lines is None:
        gripper = getattr(processor, "gripper", None)
        n_lines = 1 if gripper is None else gripper.n_lines
    if isinstance(n_lines, bool) or not isinstance(n_lines, (int, np.integer)) or not 1 <= n_lines <= 255:
        raise ArgumentError(f"n_lines: expected 1..255 pressure lines, got {n_lines!r}")
    return tuple(range(int(n_lines)))


def _clip(setpoints, lines, max_pressure_pa):
    """The set-points to send, each in [0, max]; raises ControlStop for a line or value that is no set-point."""
    if not isinstance(setpoints, dict):
        raise ControlStop(f"the controller returned {type(setpoints).__name__}, not a dict line -> pressure_pa")
    out, clipped = {}, 0
    for line, value in setpoints.items():
        if isinstance(line, bool) or not isinstance(line, (int, np.integer)) or int(line) not in lines:
            raise ControlStop(f"the controller set line {line!r}: the board has lines {lines[0]}..{lines[-1]}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            v = math.nan
        if not math.isfinite(v):
            raise ControlStop(f"the controller returned {value!r} for line {line}: not a pressure")
        c = min(max(v, 0.0), max_pressure_pa)
        clipped += c != v
        out[int(line)] = c
    return out, clipped


def _zero(driver, lines, guard) -> tuple:
    """Send set-point 0 on ``lines`` and every line the board reported; returns (the LineZero of each, when done).

    ``when done`` is the ``perf_counter`` after the last write, NaN if one failed. A line
    the board stopped reporting gets its zero too (no check against the board's latest
    frame); a write that fails does not keep the other lines from theirs.
    """
    latest = getattr(driver, "latest", lambda: None)()
    board = set(guard.board_lines) | set(range(0 if latest is None else len(sample_lines(latest.sample))))
    zeros = []
    for line in sorted(set(lines) | board):
        try:
            driver.send_setpoint(line, 0.0, check_line=False)
        except Exception as err:  # noqa: BLE001 - whatever one write raises, the other lines still get theirs
            log.error("set-point 0 on line %d could not be sent: %s", line, err)
            zeros.append(LineZero(line, False, str(err) or type(err).__name__, line in guard.reporting))
        else:
            zeros.append(LineZero(line, True, None, line in guard.reporting))
    done = time.perf_counter()
    return tuple(zeros), (done if all(z.sent for z in zeros) else math.nan)


def _confirm(driver, zeros, safety) -> tuple:
    """Watch the reported pressures of the lines zeroed for up to ``safety.confirm_s``; the zeros with what fell.

    A line has fallen at its first reading at or below ``safety.pressure_tolerance_pa``;
    the watch ends when every watched line has, or at ``confirm_s``, or when the board
    stops answering.
    """
    watched = {z.line for z in zeros if z.sent and z.reported}
    get_batch = getattr(driver, "get_batch", None)
    if not watched or not safety.confirm_s or get_batch is None:
        return zeros
    tol = safety.pressure_tolerance_pa
    last, fell = dict.fromkeys(watched, math.nan), set()
    t0 = time.monotonic()
    while fell != watched and (now := time.monotonic()) - t0 < safety.confirm_s:
        try:
            readings = get_batch(timeout=min(HEARTBEAT_S, t0 + safety.confirm_s - now))
        except DeviceError:
            break
        for r in readings:
            for line, value in enumerate(sample_lines(r.sample)):
                if line in watched and value is not None:
                    last[line] = value
                    if value <= tol:
                        fell.add(line)
    after = time.monotonic() - t0
    # a line with no reading after its zero (a board that stopped streaming) is not confirmed either way
    return tuple(dataclasses.replace(z, fell=z.line in fell if math.isfinite(last[z.line]) else None,
                                     pressure_pa=last[z.line], after_s=after)
                 if z.line in watched else z for z in zeros)


#: the default pressure limit of :func:`run` [Pa]
DEFAULT_MAX_PRESSURE_PA = 100e3


def run(driver, processor, controller, *, max_pressure_pa=DEFAULT_MAX_PRESSURE_PA, seconds=None, stop=None,
        safety=None, n_lines=None, recording=None, on_block=None) -> ControlResult:
    """Close the loop: per block of frames, process, control, clip and send set-points; zero them at the end.

    Parameters
    ----------
    driver : Driver
        An open, streaming board (with a queue) that takes set-points
        (:meth:`~bendsense.device.driver.Driver.send_setpoint`; a block's together with
        :meth:`~bendsense.device.driver.Driver.send_setpoints` where it has it) and
        heartbeats (:meth:`~bendsense.device.driver.Driver.send_heartbeat`).
    processor : LiveProcessor or gripper processor
        Its ``process_readings(readings)`` makes the block the controller gets.
    controller : callable
        ``controller(block) -> {line: pressure_pa}``; its ``fingers`` attribute (if any)
        names the fingers whose force and model status the safety checks watch (default:
        every finger of the block; empty: none, a controller that acts on no force, such as
        :class:`~bendsense.control.Sweep`).
    max_pressure_pa : float, default :data:`DEFAULT_MAX_PRESSURE_PA` (100 kPa)
        Highest set-point ever sent [Pa]: every set-point is clipped to
        ``[0, max_pressure_pa]``.
    seconds : float, optional
        Run this long [s]; None: until ``stop``, Ctrl-C, SIGTERM or a safety stop.
    stop : threading.Event, optional
        Set it (from another thread) to end the loop.
    safety : Safety, optional
        The limits of the loop's own stops (default :class:`~bendsense.control.Safety()`).
    n_lines : int, optional
        The config's pressure lines (default: the processor's gripper's, else 1): those
        the controller does not drive are held at 0; all of them, every line the board
        reported and every line driven get set-point 0 at the end.
    recording : ControlRecording, optional
        Where to record the session (readings, control log, results).
    on_block : callable, optional
        Called as ``on_block(block, setpoints)`` after each block's set-points were sent.

    Returns
    -------
    ControlResult

    Raises
    ------
    ControlStop
        A safety stop (:mod:`bendsense.control.safety`: lost frames, silence, a pressure
        beyond the limit on any line or above every set-point of the last
        ``Safety.follow_s``, a controlled finger without a force or flagged by
        the model, a controller's answer that is no set-point), after set-point 0 went to
        every line; its ``result`` holds the counters.
    KeyboardInterrupt
        Ctrl-C, SIGTERM, SIGHUP or SIGQUIT, after set-point 0 went to every line; also
        one that came while the loop zeroed (held off until then), whatever ended it.

    Notes
    -----
    Whatever the loop raises carries the counters as its ``result`` attribute (a
    :class:`ControlResult`), so that a stopped session still says what it did; its
    ``zeros`` say line by line whether set-point 0 was sent and whether the pressure fell
    (:func:`zero_report`).

    The loop reads the board's port in its own thread while it runs
    (:meth:`~bendsense.device.driver.Driver.reading_here`, where the driver has it): each
    frame reaches it as its bytes arrive, not at the reader thread's next turn at the GIL.
    """
    if isinstance(max_pressure_pa, bool) or not isinstance(max_pressure_pa, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(max_pressure_pa) and max_pressure_pa > 0):
        raise ArgumentError(f"max_pressure_pa: expected a pressure > 0 [Pa], got {max_pressure_pa!r}")
    if seconds is not None and not (isinstance(seconds, (int, float)) and seconds > 0):
        raise ArgumentError(f"seconds: expected a time > 0 [s] or None, got {seconds!r}")
    lines = _lines(processor, n_lines)
    safety = Safety() if safety is None else safety
    hello = getattr(driver, "hello", None)
    fingers = getattr(controller, "fingers", None)
    guard = Guard(safety, _fingers(processor) if fingers is None else fingers,
                  rate_hz=getattr(hello, "rate_hz", None) or None, max_pressure_pa=float(max_pressure_pa))
    state = {"frames": 0, "max": 0.0, "clipped": 0, "loop": [], "process": [], "sizes": [], "reads": [],
             "current": {}, "driven": set(), "held": (), "signals": []}
    outcome, stopped_at, zero_at, error, result = "stopped", math.nan, math.nan, None, None
    with _signals_stop(state["signals"]):
        try:
            with _prompt_threads(), getattr(driver, "reading_here", contextlib.nullcontext)():
                outcome = _loop(driver, processor, controller, seconds, stop, guard, lines, recording, on_block,
                                state)
            stopped_at = time.perf_counter()
        except BaseException as err:
            stopped_at = time.perf_counter()
            error = err
            if state["signals"] and not isinstance(err, (KeyboardInterrupt, ControlStop)):
                # the signal's KeyboardInterrupt, raised inside a call that reported its own error instead (numba's
                # unboxing of a typed list, interrupted, raises "can't unbox ..."): the signal stopped the loop
                error = KeyboardInterrupt()
            outcome = "interrupted" if isinstance(error, KeyboardInterrupt) else f"{type(err).__name__}: {err}"
            if isinstance(err, ControlStop):
                outcome = f"safety stop: {err.reason}"
            if error is not err:
                raise error from err
            raise
        finally:
            try:
                with deferred():  # a second Ctrl-C (or a SIGHUP) acts after every line has its zero and its record
                    zeros, zero_at = _zero(driver, set(lines) | set(state["current"]), guard)  # first of all
                    zeros = _confirm(driver, zeros, guard.safety)
                    result = ControlResult(
                        frames=state["frames"], blocks=len(state["loop"]), outcome=outcome,
                        lines=tuple(z.line for z in zeros), max_setpoint_pa=state["max"], clipped=state["clipped"],
                        zero_latency_s=zero_at - stopped_at, stopped_at_s=stopped_at,
                        loop_s=np.asarray(state["loop"]), process_s=np.asarray(state["process"]),
                        block_frames=np.asarray(state["sizes"], dtype=np.int64),
                        block_reads=np.asarray(state["reads"], dtype=np.int64), zeros=zeros,
                        held=tuple(k for k in state["held"] if k not in state["driven"]))
                    if error is not None:
                        with contextlib.suppress(AttributeError, TypeError):  # a user's exception may not take them
                            error.result = result
                    if recording is not None:
                        recording.close(outcome)
            except KeyboardInterrupt as late:  # a stop signal held off while zeroing, acted on now
                late.result = result
                raise
    return result


def _fingers(processor) -> tuple:
    gripper = getattr(processor, "gripper", None)
    return (None,) if gripper is None else tuple(gripper.names)


def _send(driver, setpoints) -> None:
    """A block's set-points: in one write where the driver can, else line by line.

    :meth:`~bendsense.device.driver.Driver.send_setpoints`; a driver of one's own may have
    ``send_setpoint`` only.
    """
    many = getattr(driver, "send_setpoints", None)
    if many is not None:
        many(setpoints, check_line=False, drain=False)  # the zeros at the end wait for the port
        return
    for line, value in setpoints.items():
        driver.send_setpoint(line, value, check_line=False)


def _loop(driver, processor, controller, seconds, stop, guard, lines, recording, on_block, state) -> str:
    """The loop of :func:`run` until its time or a stop; returns the outcome (set-points within the guard's limit)."""
    t0 = time.monotonic()
    last_frame, started = t0, False
    silence = guard.silence_s
    beat, beat_failed = -math.inf, False
    while True:
        if state["signals"]:  # a stop signal whose KeyboardInterrupt did not reach the loop
            raise KeyboardInterrupt
        now = time.monotonic()
        if now - beat >= HEARTBEAT_S:  # the board's watchdog: the loop is alive, set-points or not
            beat = now
            try:
                driver.send_heartbeat()
                beat_failed = False
            except DeviceError as err:  # a board that takes no frames: its silence or the next set-point stops the loop
                if not beat_failed:  # once while they fail, not every 50 ms
                    log.warning("heartbeat not sent: %s", err)
                beat_failed = True
        if stop is not None and stop.is_set():
            return "stopped"
        if seconds is not None and now - t0 >= seconds:
            return "duration reached"
        wait = silence if seconds is None else min(silence, max(t0 + seconds - now, 0.0))
        readings = driver.get_batch(timeout=max(min(wait, HEARTBEAT_S - (now - beat)), 1e-4))
        now = time.monotonic()
        if not readings:
            guard.silent(now - last_frame, started)
            continue
        last_frame, started = now, True
        tic = time.perf_counter()
        guard.lost(driver.stats, now)
        guard.pressures(readings, now)
        block = processor.process_readings(readings)
        processed = time.perf_counter()
        guard.flags(block)
        setpoints, clipped = _clip(controller(block), lines, guard.max_pressure_pa)
        state["driven"].update(setpoints)
        if not state["loop"]:  # the first block: the lines the controller does not drive are held at 0
            state["held"] = tuple(k for k in lines if k not in setpoints)
            setpoints = {**dict.fromkeys(state["held"], 0.0), **setpoints}
        _send(driver, setpoints)
        guard.sent(setpoints, now)
        state["loop"].append(time.perf_counter() - tic)
        state["process"].append(processed - tic)
        state["sizes"].append(len(readings))
        state["reads"].append(len({r.host_ns for r in readings}))
        state["frames"] += len(readings)
        state["clipped"] += clipped
        if setpoints:
            state["max"] = max(state["max"], max(setpoints.values()))
            state["current"].update(setpoints)
        if recording is not None:
            recording.write_readings(readings)
            recording.write_block(readings, block, state["current"], lines, controller)
        if on_block is not None:
            on_block(block, setpoints)

