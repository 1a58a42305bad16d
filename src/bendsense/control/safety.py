"""The control loop's safety model: when it stops by itself, and what it lets go.

A force loop drives a pressure into a soft finger pressing a real object and may be left
running unattended: whatever goes wrong, the loop must let go, and say truthfully what it
did. The model, in full (docs/grasping.md, "Safety", lists every stop with the test that
provokes it on a fake board):

**Letting go.** Whatever ends :func:`bendsense.control.run` — its time, a stop event,
Ctrl-C, SIGTERM, one of the stops below, an error in the controller or the processor, a
failing device — set-point 0 goes first, before anything is closed, to the union of

- every line of the config (``n_lines``: the processor's gripper's lines, else line 0),
- every line the loop ever drove (the controller's set-points and the held lines below),
- every line the board ever reported a pressure on, over the whole run (not only in its
  latest frame): a line the board stopped reporting may still be pressurised, so its
  zero is sent anyway (``Driver.send_setpoint(..., check_line=False)``).

Each line's zero is recorded (:class:`~bendsense.control.loop.LineZero` in
:attr:`ControlResult.zeros`): sent, or could not be sent (the write's error), and
whether the board's latest frame reports that line's pressure at all (a line it does
not report cannot be confirmed to fall). No message says "sent" of a line whose write
failed; ``bendsense control`` exits non-zero when a zero could not be sent.

**Holding.** Lines the controller does not drive (``--finger`` on a gripper: the other
fingers' lines; a board's own scripted profile would drive them) get set-point 0 with
the first block and are held there (:attr:`ControlResult.held`); every set-point sent on
any line is clipped to ``[0, max_pressure_pa]`` whatever the controller returns.

**Stopping** (:class:`Guard` checks each block against :class:`Safety`'s limits and
raises :class:`ControlStop`):

- **lost frames**: more than ``max_lost_frames`` frames lost (sequence gaps, the
  driver's queue drops) within ``lost_window_s``: the loop no longer sees every frame;
- **silence**: no frame for ``silence_s`` (a board that stopped streaming or died; by
  default 0.1 s or 10 frame periods, whichever is longer), or none within
  ``first_frame_s`` of the start (a board that never starts: nothing was sent yet);
- **pressure**: a pressure any line of the board reports above ``max_pressure_pa`` by
  more than ``pressure_tolerance_pa`` (5 kPa: a proportional regulator's ripple and
  accuracy, about ±1 % of a 200 kPa full scale, and a small overshoot after a step, with
  room), or below ``-pressure_tolerance_pa`` (no gauge pressure a regulator makes): a
  line the loop does not hold, a stuck regulator or a failed pressure sensor, stopped at
  the first such frame;
- **a board that does not follow its set-points**: a line's reported pressure above every
  set-point the host sent it within the last ``follow_s`` by more than
  ``pressure_tolerance_pa`` (a board that ignores SETPOINTs, a stuck regulator). A
  first-order regulator's pressure never passes the highest set-point of its past, and
  what is left of an older, higher one after a time T is ``exp(-T/τ)`` of the
  difference: below 5 kPa of a 200 kPa full scale after ``τ ln 40 ≈ 3.7 τ``; 0.25 s is
  that for a slow regulator (τ = 50 ms; the simulated one has 25 ms) with room. Taking
  the highest set-point of the window (not the last one) keeps a slew-limited fall of the
  set-point, however slow, from looking like a fault;
- **no force**: a controlled finger without a force of its own (NaN: no pressure
  reading, a pressure outside the config's ``actuator.pressure_range_pa``, a shape with
  no estimate) for ``flagged_s``: the loop would act blind;
- **the model**: a controlled finger ``model_misfit`` or ``not_identifiable`` for
  ``flagged_s`` in a row. A frame's own χ² is beyond chance in 0.1 % of frames by
  design (``MISFIT_P``), once a second at 1 kHz: one such frame does not stop a grasp;
  a window test that fails (DESIGN.md section 2b: 50 ms, what catches a persistent model
  error) flags every frame until the next window closes, and a shape the model cannot
  match flags every frame: both stop the loop within ``flagged_s``;
- **a controller's answer** that is no set-point (not a dict, a value that is not a
  finite number, a line outside the config's): checked by the loop itself.

After the zeros, the loop watches the board's pressures for up to ``confirm_s`` (0.5 s:
ten time constants of the slow regulator above) and records, line by line, whether each
fell below ``pressure_tolerance_pa`` (:class:`~bendsense.control.LineZero`); a line that
still reads high is said, and ``bendsense control`` exits 1.

No-force and model frames make one run: a finger that cannot be trusted for
``flagged_s``, whichever the reason of each frame, stops the loop. A held line (no
controller drives it) that stops reporting does not stop it: it was set to 0, nothing
acts on its pressure, and it gets its zero again at the end.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from bendsense.control.pi import finger_block
from bendsense.errors import ArgumentError, BendsenseError
from bendsense.pipeline.readings import sample_lines
from bendsense.status import Status, words

__all__ = ["Safety", "Guard", "ControlStop", "STOP_STATUSES"]

#: the shortest silence limit [s] (a faster board's default; a slower one's is 10 frame periods)
DEFAULT_SILENCE_S = 0.1
#: a controlled finger's statuses that stop the loop when they last ``flagged_s``
STOP_STATUSES = (Status.MODEL_MISFIT, Status.NOT_IDENTIFIABLE)
_STOPPING = np.isin(np.arange(max(Status) + 1), STOP_STATUSES)  # by status code: whether it is one of them


class ControlStop(BendsenseError, RuntimeError):
    """The control loop stopped itself (a safety check); set-point 0 went to every line (``result.zeros``).

    Attributes
    ----------
    reason : str
        What stopped it (the message).
    result : ControlResult or None
        The loop's counters, attached by :func:`bendsense.control.run`.
    """

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason
        self.result = None

    def __reduce__(self):
        return (type(self), (self.reason,))


def _number(name, value, *, integer=False):
    kinds = (int, np.integer) if integer else (int, float, np.integer, np.floating)
    if isinstance(value, bool) or not isinstance(value, kinds) or not (math.isfinite(value) and value >= 0):
        raise ArgumentError(f"{name}: expected a {'whole ' if integer else ''}number >= 0, got {value!r}")
    return value


@dataclass(frozen=True, kw_only=True)
class Safety:
    """The limits of the control loop's own stops (module docstring).

    Parameters
    ----------
    max_lost_frames : int, default 10
        Frames that may be lost within ``lost_window_s`` (more: stop).
    lost_window_s : float, default 1.0
        The window of the lost-frame count [s].
    silence_s : float, optional
        Longest time without a frame [s]; None (default): 0.1 s or 10 frame periods of the
        board (its HELLO's rate), whichever is longer.
    flagged_s : float, default 0.01
        Longest run of a controlled finger's ``model_misfit`` / ``not_identifiable``
        frames [s] (by the frames' clock).
    first_frame_s : float, default 2.0
        Longest wait for the first frame after the loop starts [s].
    pressure_tolerance_pa : float, default 5e3
        How far a line's reported pressure may pass the pressure limit (or fall below 0),
        or every set-point of the last ``follow_s``, before the loop stops; after the zeros,
        the pressure below which a line has fallen [Pa] (module docstring).
    follow_s : float, default 0.25
        How long a line's pressure may take to follow its set-points [s]: a reading above
        every set-point the host sent the line within this time (+ the tolerance) stops
        the loop (module docstring: 3.7 time constants of a 50 ms regulator, with room).
    confirm_s : float, default 0.5
        After the zeros, the longest the loop watches the reported pressures fall [s]
        (0: not watched).
    """

    max_lost_frames: int = 10
    lost_window_s: float = 1.0
    silence_s: float | None = None
    flagged_s: float = 0.01
    first_frame_s: float = 2.0
    pressure_tolerance_pa: float = 5e3
    follow_s: float = 0.25
    confirm_s: float = 0.5

    def __post_init__(self):
        _number("max_lost_frames", self.max_lost_frames, integer=True)
        for name in ("lost_window_s", "silence_s", "flagged_s", "first_frame_s", "pressure_tolerance_pa",
                     "follow_s", "confirm_s"):
            if getattr(self, name) is not None or name != "silence_s":
                _number(name, getattr(self, name))
        for name in ("silence_s", "first_frame_s", "follow_s"):
            if getattr(self, name) is not None and not getattr(self, name) > 0:
                raise ArgumentError(f"{name}: expected a time > 0 [s], got {getattr(self, name)!r}")


class Guard:
    """The running checks of one control session (:class:`Safety`'s limits).

    Parameters
    ----------
    safety : Safety
        The limits.
    fingers : sequence of str or None
        The controlled fingers (None: a single actuator).
    rate_hz : float, optional
        The board's frame rate [Hz] (for the default silence).
    max_pressure_pa : float, optional
        The loop's pressure limit [Pa]; None: no pressure watch.

    Attributes
    ----------
    silence_s : float
        The silence limit in force [s].
    board_lines : set of int
        Every line the board reported a pressure on, over the whole session.
    reporting : set of int
        The lines with a pressure reading in the latest frame checked.
    """

    def __init__(self, safety: Safety, fingers, rate_hz=None, max_pressure_pa=None):
        self.safety = safety
        self.fingers = tuple(fingers)
        default = max(DEFAULT_SILENCE_S, 10.0 / rate_hz) if rate_hz else DEFAULT_SILENCE_S
        self.silence_s = default if safety.silence_s is None else float(safety.silence_s)
        tol = safety.pressure_tolerance_pa
        self._pressure_band = (-tol, math.inf if max_pressure_pa is None else max_pressure_pa + tol)
        self.max_pressure_pa = max_pressure_pa
        self.board_lines = set()
        self.reporting = set()
        self._reported = 0  # the most lines a frame carried so far
        self._lost = collections.deque()  # (host time [s], frames lost since the previous block)
        self._lost_total = None
        self._flag_start = {f: math.nan for f in self.fingers}
        # per line: when the host first sent it a set-point, and [sent at, value, superseded at] of the sends
        # whose value no later send reached (a sliding maximum over follow_s)
        self._first_sent = {}
        self._sent = collections.defaultdict(collections.deque)

    def sent(self, setpoints, now_s: float) -> None:
        """Note the set-points just sent (for the check that the board follows them).

        Parameters
        ----------
        setpoints : dict of int to float
            Line -> set-point sent [Pa].
        now_s : float
            Host time [s].
        """
        for line, value in setpoints.items():
            sends = self._sent[line]
            self._first_sent.setdefault(line, now_s)
            if sends and math.isinf(sends[-1][2]):
                sends[-1][2] = now_s
            while sends and sends[-1][1] <= value:
                sends.pop()
            sends.append([now_s, value, math.inf])

    def _followed(self, line, now_s) -> float:
        """The highest set-point in force on ``line`` within the last ``follow_s`` [Pa] (inf: too early to say)."""
        start = now_s - self.safety.follow_s
        if self._first_sent.get(line, math.inf) > start:
            return math.inf
        sends = self._sent[line]
        while sends[0][2] <= start:
            sends.popleft()
        return sends[0][1]

    def lost(self, stats, now_s: float) -> None:
        """Check the driver's lost frames (sequence gaps and queue drops) over the window.

        Parameters
        ----------
        stats : DeviceStats
            The driver's counters now.
        now_s : float
            Host time [s].
        """
        total = int(stats.lost) + int(stats.queue_drops)
        if self._lost_total is None:
            self._lost_total = total
        new, self._lost_total = total - self._lost_total, total
        window = self._lost
        if new:
            window.append((now_s, new))
        while window and window[0][0] < now_s - self.safety.lost_window_s:
            window.popleft()
        count = sum(n for _, n in window)
        if count > self.safety.max_lost_frames:
            raise ControlStop(f"{count} frames lost within {self.safety.lost_window_s:g} s (limit "
                              f"{self.safety.max_lost_frames}): the loop no longer sees every frame")

    def pressures(self, readings, now_s: float = math.nan) -> None:
        """Note the lines the board reports and stop on a pressure outside ``[-tol, max_pressure_pa + tol]``.

        Or above every set-point the host sent the line within ``follow_s`` (+ tol): the
        board does not follow its set-points.

        Parameters
        ----------
        readings : list of Reading
            The driver's readings of the block (every line of each SAMPLE).
        now_s : float, optional
            Host time [s] (NaN: the set-points are not checked).
        """
        lo, hi = self._pressure_band
        tol = self.safety.pressure_tolerance_pa
        followed = {k: self._followed(k, now_s) + tol for k in self._first_sent} if math.isfinite(now_s) else {}
        for r in readings:
            values = sample_lines(r.sample)
            if len(values) > self._reported:
                self._reported = len(values)
                self.board_lines.update(range(len(values)))
            for line, value in enumerate(values):
                if value is not None and not lo <= value <= hi:
                    if value > hi:
                        why = (f"beyond the pressure limit {self.max_pressure_pa / 1e3:g} kPa (+{tol / 1e3:g} kPa for "
                               "regulator ripple): a line the loop does not hold, a stuck regulator or a failed "
                               "pressure sensor")
                    else:
                        why = (f"below 0 (-{tol / 1e3:g} kPa tolerance), no gauge pressure a regulator makes: a failed "
                               "sensor")
                    raise ControlStop(f"line {line} reads {value / 1e3:.4g} kPa at seq {r.sample.seq}, {why}")
                if value is not None and value > followed.get(line, math.inf):
                    raise ControlStop(
                        f"line {line} reads {value / 1e3:.4g} kPa at seq {r.sample.seq}, above every set-point sent "
                        f"to it for {self.safety.follow_s:g} s (at most {(followed[line] - tol) / 1e3:.4g} kPa, "
                        f"+{tol / 1e3:g} kPa): the board does not follow its set-points (it ignores them, or its "
                        "regulator is stuck)")
        if readings:
            self.reporting = {k for k, v in enumerate(sample_lines(readings[-1].sample)) if v is not None}

    def silent(self, since_s: float, started: bool = True) -> None:
        """Stop when no frame arrived for longer than ``silence_s`` (before the first: ``first_frame_s``).

        Parameters
        ----------
        since_s : float
            Time since the latest frame (since the start, before the first frame) [s].
        started : bool, default True
            Whether a frame has arrived yet.
        """
        if not started:
            if since_s > self.safety.first_frame_s:
                raise ControlStop(f"no frame from the board within {self.safety.first_frame_s:g} s of the start "
                                  "(is it streaming?)")
            return
        if since_s > self.silence_s:
            raise ControlStop(f"no frame from the board for {since_s:.3g} s (limit {self.silence_s:g} s)")

    def flags(self, block) -> None:
        """Stop when a controlled finger has had no force, or been flagged by the model, for ``flagged_s``.

        A frame counts when its force (or the tracked one, where the block is tracked: what a
        controller acts on) is not a number (no pressure reading, a pressure outside the
        config's range, no estimate, a component the constraint leaves free) or its status
        is ``model_misfit`` / ``not_identifiable``; a run of such frames for ``flagged_s``
        stops the loop.

        Parameters
        ----------
        block : LiveBlock or dict of str to LiveBlock
            The processor's result for the block.
        """
        for finger in self.fingers:
            own = finger_block(block, finger)  # its arrays: a block's objects are made only when asked for
            track_status = own.track_status
            status = own.status if track_status is None else track_status
            force = np.asarray(own.force_n, dtype=float).reshape(len(own), -1)
            tracked = None if track_status is None else own.track_force_n  # the force the controller acts on
            stopping = _STOPPING[status]
            # the usual block, in a few whole-array operations: nothing flagged, every force a number (a sum of
            # numbers is one unless it overflows, which the frame-by-frame look below then clears)
            if not stopping.any() and math.isfinite(force.sum() + (0.0 if tracked is None else tracked.sum())):
                self._flag_start[finger] = math.nan
                continue
            blind = ~np.isfinite(force).all(axis=1)
            if tracked is not None:
                blind |= ~np.isfinite(tracked).all(axis=1)
            flagged = stopping | blind
            reason = words(status).astype(object)
            if blind.any():  # the frame's own status says why it has no force (no_pressure, out of range, ...)
                reason = np.where(blind & ~stopping, [f"no force ({w})" for w in words(own.status).tolist()], reason)
            start = self._flag_start[finger]
            for t, bad, what in zip(own.t_s.tolist(), flagged.tolist(), reason.tolist()):
                if not bad:
                    start = math.nan
                    continue
                if math.isnan(start):
                    start = t
                if t - start >= self.safety.flagged_s - 1e-9:  # frame times are whole µs: 10 ms is 10 ms
                    name = "" if finger is None else f"finger {finger}: "
                    raise ControlStop(f"{name}{what} for {(t - start) * 1e3:.3g} ms (limit "
                                      f"{self.safety.flagged_s * 1e3:g} ms) at t = {t:.3f} s: the force cannot be "
                                      "trusted")
            self._flag_start[finger] = start
