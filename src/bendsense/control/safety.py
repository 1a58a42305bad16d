"""When the loop stops by itself: the checks of :func:`bendsense.control.run` on every block.

A force loop drives a pressure into a soft finger pressing a real object: whatever goes
wrong, the loop must let go. :class:`Safety` holds the limits, :class:`Guard` checks
each block against them and raises :class:`ControlStop` (the loop then sends set-point 0
on every line before anything else):

- **lost frames**: more than ``max_lost_frames`` frames lost (sequence gaps, the
  driver's queue drops) within ``lost_window_s``: the loop no longer sees every frame;
- **silence**: no frame for ``silence_s`` (a board that stopped streaming; by default 0.1 s
  or 10 frame periods, whichever is longer), or none within
  ``first_frame_s`` of the start (a board that never starts: nothing was sent yet);
- **the model**: a controlled finger ``model_misfit`` or ``not_identifiable`` for
  ``flagged_s`` in a row. A frame's own χ² is beyond chance in 0.1 % of frames by
  design (``MISFIT_P``), once a second at 1 kHz: one such frame does not stop a grasp;
  a window test that fails (DESIGN.md section 2b: 50 ms, what catches a persistent model
  error) flags every frame until the next window closes, and a shape the model cannot
  match flags every frame: both stop the loop within ``flagged_s``.

The pressure limit is not a check: :func:`~bendsense.control.run` clips every set-point
to ``[0, max_pressure_pa]`` before it is sent, whatever the controller returns.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass

import numpy as np

from bendsense.errors import ArgumentError, BendsenseError
from bendsense.results import MODEL_MISFIT, NOT_IDENTIFIABLE

__all__ = ["Safety", "Guard", "ControlStop", "STOP_STATUSES"]

#: the shortest silence limit [s] (a faster board's default; a slower one's is 10 frame periods)
DEFAULT_SILENCE_S = 0.1
#: a controlled finger's statuses that stop the loop when they last ``flagged_s``
STOP_STATUSES = (MODEL_MISFIT, NOT_IDENTIFIABLE)


class ControlStop(BendsenseError, RuntimeError):
    """The control loop stopped itself (a safety check); every line's set-point was set to 0.

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
    """

    max_lost_frames: int = 10
    lost_window_s: float = 1.0
    silence_s: float | None = None
    flagged_s: float = 0.01
    first_frame_s: float = 2.0

    def __post_init__(self):
        _number("max_lost_frames", self.max_lost_frames, integer=True)
        for name in ("lost_window_s", "silence_s", "flagged_s", "first_frame_s"):
            if getattr(self, name) is not None or name != "silence_s":
                _number(name, getattr(self, name))
        for name in ("silence_s", "first_frame_s"):
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

    Attributes
    ----------
    silence_s : float
        The silence limit in force [s].
    """

    def __init__(self, safety: Safety, fingers, rate_hz=None):
        self.safety = safety
        self.fingers = tuple(fingers)
        default = max(DEFAULT_SILENCE_S, 10.0 / rate_hz) if rate_hz else DEFAULT_SILENCE_S
        self.silence_s = default if safety.silence_s is None else float(safety.silence_s)
        self._lost = collections.deque()  # (host time [s], frames lost since the previous block)
        self._lost_total = None
        self._flag_start = {f: math.nan for f in self.fingers}

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
        """Stop when a controlled finger has been ``model_misfit`` / ``not_identifiable`` for ``flagged_s``.

        Parameters
        ----------
        block : LiveBlock or dict of str to LiveBlock
            The processor's result for the block.
        """
        from bendsense.control.pi import finger_block

        for finger in self.fingers:
            own = finger_block(block, finger)
            status = np.asarray(own.track.status if own.track is not None else own.status, dtype=object)
            flagged = np.isin(status, STOP_STATUSES)
            start = self._flag_start[finger]
            for t, bad, what in zip(own.t_s.tolist(), flagged.tolist(), status.tolist()):
                if not bad:
                    start = math.nan
                    continue
                if math.isnan(start):
                    start = t
                if t - start >= self.safety.flagged_s:
                    name = "" if finger is None else f"finger {finger}: "
                    raise ControlStop(f"{name}{what} for {(t - start) * 1e3:.3g} ms (limit "
                                      f"{self.safety.flagged_s * 1e3:g} ms) at t = {t:.3f} s: the force cannot be "
                                      "trusted")
            self._flag_start[finger] = start
